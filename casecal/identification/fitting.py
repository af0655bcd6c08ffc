"""Small pieces every `identify` entry shares: problems kept for reuse, the verdict of a
fit, option checks and the start's RMS (the one fitting path's, not any sensor's)."""

from __future__ import annotations

from numbers import Integral, Real

import numpy as np

from ..errors import CalibrationError
from .calibration import STATUS_MESSAGES
from .facts import point_rms
from .problem import Problem

SHARED_PROBLEMS = 3
"""Problems `shared_problems` keeps for reuse (they share one memo; each holds its weights)."""


def shared_problems(make):
    """`make` returning the same `Problem` for the same robot and columns, and Problems
    that share one memo of evaluations and reductions, so that the rounds, the solver and
    the audit evaluate a point once (a pass over a million poses costs a second). Lives as
    long as one `identify` call."""
    kept: dict = {}
    memo: dict = {}  # one for all: the same data arrays, keyed by the parameter vector

    def shared(robot, names, kernel_names=None, **other):
        if other:
            return make(robot, names=names, kernel_names=kernel_names, **other)
        at = (robot.structure, robot.vector().tobytes(), tuple(names))
        key = (*at, tuple(kernel_names or names))
        problem = kept.pop(key, None)
        if problem is None:
            same = [p for k, p in kept.items() if k[:3] == at]  # other columns, same point
            problem = (
                same[-1].with_kernel(key[3])
                if same
                else make(robot, names=names, kernel_names=kernel_names, memo=memo)
            )
        kept[key] = problem  # the latest last
        while len(kept) > SHARED_PROBLEMS:
            kept.pop(next(iter(kept)))
        return problem

    return shared


def verdict(checks, solver_status: int, solver_message: str | None) -> tuple[int, str]:
    """A Calibration's status and message: the audit's verdict over the solver's."""
    if not checks.passed:
        first, *more = checks.failures
        also = f" (also failed: {', '.join(c.name for c in more)})" if more else ""
        return -2, f"failed the answer audit: {first.name}: {first.text}{also}"
    if solver_status > 0:
        return solver_status, solver_message or STATUS_MESSAGES[solver_status]
    return 6, STATUS_MESSAGES[6]


def check_iterations(max_iterations, tolerance) -> tuple[int, float]:
    """`max_iterations` and `tolerance` as int and float, or a CalibrationError saying why."""
    if isinstance(max_iterations, bool) or not isinstance(max_iterations, Integral):
        raise CalibrationError(f"max_iterations must be a positive integer, got {max_iterations!r}")
    if max_iterations < 1:
        raise CalibrationError(f"max_iterations must be a positive integer, got {max_iterations!r}")
    if isinstance(tolerance, bool) or not (isinstance(tolerance, Real) and 0 < tolerance < 1):
        raise CalibrationError(f"tolerance must be a number between 0 and 1, got {tolerance!r}")
    return int(max_iterations), float(tolerance)


def rms_of(problem: Problem, k: int) -> float:
    """`point_rms` of `problem` at its start, measured coordinates only."""
    return point_rms(problem.point_residuals(np.zeros(k)), problem._unmeasured)


def outcome_fields(out, got) -> dict:
    """The `Calibration` fields every fit takes from where its rounds ended (`out`,
    `casecal.identification.rounds.Outcome`) and what was gathered there (`got`,
    `casecal.identification.facts.Gathered`)."""
    return {
        "estimated": out.estimated,
        "iterations": out.iterations,
        "history": out.history,
        "observability": out.end_analysis,
        "solver_status": out.solver_status,
        "pruned": out.pruned,
        "frozen": out.frozen,
        "start_observability": out.start_analysis,
        "rounds": out.rounds,
        "joined": out.joined,
        "pose_blind": got.facts.blind_here,
        "still_joints": got.facts.still,
        "outliers": got.outliers,
    }
