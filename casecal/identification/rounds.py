"""The fit in rounds: estimate a base set, look again where the fit ended, repeat.

What the data can see depends on where the robot model is linearised. At a nominal robot
whose tool point sits on the wrist's axes, the wrist's angles move nothing; at the true
robot, a few millimetres off those axes, they do. And a parameter the poses determine only
to within metres is no estimate at all. So a fit runs in rounds:

1. estimate the structural base set at the start (`casecal.identification.analysis`;
   frames first, so the held parameters are joint parameters at their nominal values);
2. where the fit ended, analyse again. A parameter that has become visible joins the set;
   it never replaces one already estimated (a wrist angle that a fitted 45 µm tool offset
   makes visible must not stand in for that offset), and if a dependency appears, the
   latest to join yields. A parameter the data do not determine is held (the
   *noise-aware rank*, `prune`);
3. repeat until the set no longer changes (at most `MAX_ROUNDS`).

When the noise-aware rank holds a parameter, the next round starts over from the start
(every held parameter at its start value, nominal in the fit frame): what was fitted
beside a parameter the data cannot determine may carry its wild values. A parameter that
was estimated in an earlier round and is only structurally blind where the fit ended goes
back to its start value when that changes nothing measured, and otherwise keeps the value
it was fitted to while visible: any value fits as well there, and resetting it would only
be compensated to first order. Gauss-Newton
that stalls in a curved valley is continued by Levenberg-Marquardt within the round. The
one-shot ``"svd"`` method is the paper's procedure and runs a single round without pruning.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ..design.poses import uniform
from ..errors import CalibrationError
from ..model.robot import Robot
from ..model.rotation_chart import deviations_between
from ..observations.rig import moves_robot
from .analysis import Observability, analyse, pivot_order
from .outliers import outlier_poses
from .problem import Problem
from .rank import WIDE, held_gain, held_matter, prune
from .solvers import SOLVERS, floor_cost

MAX_ROUNDS = 6
"""Rounds of fit-and-look-again before a fit whose identifiable set keeps changing stops."""

LOSSES = ("linear", "huber", "soft_l1")


@dataclass(frozen=True)
class Settings:
    """How to solve each round (see `casecal.identify` for the meaning of each)."""

    method: str
    max_iterations: int
    tolerance: float
    known: bool
    w: np.ndarray
    loss: str = "linear"
    loss_scale: float = 3.0
    bounds: dict = field(default_factory=dict)
    prior: dict = field(default_factory=dict)
    progress: Callable[[str], None] | None = None
    """Called with a line on each iteration of a long fit (the caller decides to show it)."""
    damped_after_stall: bool = True
    """Whether Levenberg-Marquardt goes on where Gauss-Newton stalls within a round. Off
    for distances: where a planar arm's fit stalls on its flat point, the damped steps
    crawl along the blind tilts to far values, and the next round's look at the
    identifiable set (another base set there) is what moves it on."""
    frames_first: bool = True
    """Whether the frames are offered to the base set first (`pivot_order`: a frame absorbs
    what duplicates it exactly, as a tracker's points see it). Off for distances, which
    see no base frame and whose tool offsets the analysis orders like any parameter."""


@dataclass(frozen=True)
class Outcome:
    """Where the rounds ended.

    Attributes
    ----------
    robot : Robot
        The fitted robot (fit frame).
    estimated : tuple of str
        In the canonical order of the asked-for names (as `Robot.position_jacobian` orders
        its columns, so the covariance pairs with it).
    pruned : dict of str to str
        Parameters held at their start values because the data do not determine them,
        with the reason.
    unsupported : tuple of str
        Those of `pruned` whose uncertainty alone would have moved the tool across the
        workspace by more than the uncalibrated error: the poses do not support them.
    frozen : dict of str to str
        Parameters estimated in an earlier round that are blind where the fit ended,
        held at the value they were fitted to while visible, with the reason.
    iterations, solver_status : int
    message : str or None
    history : tuple of float
        Cost after each iteration of every round.
    weights : ndarray, shape (N, m)
        Robust-loss weights of the measured points (ones for least squares).
    start_analysis, end_analysis : Observability
        At the start of the fit and where it ended.
    start_robot : Robot
        Where the fit started (fit frame).
    rounds : int
    settled : bool
        Whether the estimated set stopped changing before `MAX_ROUNDS`.
    joined : tuple of str
        Parameters blind at the start that the later rounds estimated.
    """

    robot: Robot
    estimated: tuple[str, ...]
    pruned: dict
    unsupported: tuple[str, ...]
    frozen: dict
    iterations: int
    solver_status: int
    message: str | None
    history: tuple[float, ...]
    weights: np.ndarray
    start_analysis: Observability
    end_analysis: Observability
    start_robot: Robot
    rounds: int
    settled: bool
    joined: tuple[str, ...]


def fit_in_rounds(make, start: Robot, names, settings: Settings, e0: float) -> Outcome:
    """Fit `names` from `start` in rounds (module doc).

    Parameters
    ----------
    make : callable(robot, names=...) -> Problem
        Builds the problem of the measurements at a robot.
    start : Robot
        Start of the fit; parameters held for the noise keep its values.
    names : sequence of str
        The asked-for parameters.
    settings : Settings
    e0 : float
        RMS position error at the start, m: the uncalibrated error that a parameter's
        uncertainty must not exceed (never less than the noise, √3 σ RMS, when σ is known:
        data that match the nominal robot to their noise bound no deviation below it).
    """
    if settings.known:
        e0 = max(e0, float(np.sqrt(3 * np.mean(1.0 / measured_weights(settings.w) ** 2))))
    hold = start.parameters
    start_analysis = check_analysis(make(start, names=names))
    q_work = workspace_poses(start)
    offered = pivot_order(names) if settings.frames_first else range(len(names))
    order = [names[i] for i in offered if names[i] in start_analysis.base_parameters]
    point, weights = start, np.ones((start_analysis.n_poses, make(start, names=names).m))
    iterations, history, pruned, frozen, seen, protected = 0, [], {}, {}, [], set()
    end_analysis, settled, restarted = start_analysis, False, False
    rounds = 0
    for rounds in range(1, MAX_ROUNDS + 1):
        restarted = False
        point, its, status, hist, message, weights = _solve_round(
            make, point, names, order, settings, weights, hold, rounds
        )
        iterations += its
        history += hist if not history else hist[1:]
        if settings.method == "svd" or status < 0:
            # the paper's one linearisation: what it saw is what it saw at the start
            settled = True
            break
        # with every parameter's columns: the audit reuses this pass where the fit ends
        every = [*names, *(n for n in start.parameter_names if n not in names)]
        full = _problem(make, point, names, settings, weights, kernel_names=every)
        r = full.residual(np.zeros(len(names)))
        linear = full.reduced(np.zeros(len(names)), r)
        end_analysis = analyse(linear.R, names, full.q.shape[0], prefer=order)
        base = end_analysis.base_parameters
        visible = [n for n in order if n in base]
        visible += [
            names[i]
            for i in offered
            if names[i] in base and names[i] not in order and names[i] not in pruned
        ]
        point, lost = _release(make, point, names, settings, weights, hold, order, base, r)
        del r  # N rows: not kept alive through the next round's solve
        frozen.update(dict.fromkeys(lost, FROZEN))
        # what an uncertainty costs the robot: not a camera rig's own poses and lens
        J_work = workspace_jacobian(point, q_work, names, full) * moves_robot(point, names)
        noise = (
            float(np.sqrt(3 * np.mean(1.0 / measured_weights(settings.w) ** 2)))
            if settings.known
            else None
        )
        moved = deviations_between(hold, point.parameters, visible)  # rotations: a turn
        offsets = np.array([moved[n] for n in visible])
        keep, dropped = prune(
            linear,
            names,
            visible,
            offsets,
            settings.known,
            e0,
            J_work,
            noise,
            set(order),
            protected,
            start.sizes,
        )
        pruned.update(dropped)
        seen.append(frozenset(order))
        held_now = bool(dropped)  # held parameters are never candidates again: progress
        dropped = [n for n in dropped if n in order]  # newcomers held at once were never fitted
        if set(keep) <= set(order) and not dropped:
            # nothing joined and nothing was held for the noise: what left is blind here
            # and keeps its fitted value, and a minimum over the larger set is one over
            # the rest with it fixed, so the fit has settled where it stands
            order = keep
            misjudged = _held_that_matter(linear, names, order, pruned, settings)
            if not misjudged or set(misjudged) <= protected:
                settled = True
                break
            # the data see what was held as useless: estimate it after all (once)
            protected |= set(misjudged)
            for n in misjudged:
                del pruned[n]
            order = [*order, *misjudged]
            continue
        if frozenset(keep) in seen and not held_now:
            break  # the same set again with nothing newly held: a cycle
        if dropped:
            # what was fitted beside a parameter the data cannot determine may carry its
            # wild values: start over, with every held parameter at its start value
            point = start
            frozen = {}
            restarted = True
        order = keep
    if restarted:
        # the rounds ran out right after a restart: fit what is kept once more, or the
        # robot returned would be the start's while its estimates are said to be fitted
        point, its, status, hist, message, weights = _solve_round(
            make, point, names, order, settings, weights, hold, rounds + 1
        )
        iterations += its
        history += hist[1:]
    return Outcome(
        robot=point,
        estimated=tuple(n for n in names if n in order),
        pruned={n: why for n, why in pruned.items() if n not in order},
        unsupported=tuple(n for n, why in pruned.items() if n not in order and WIDE in why),
        frozen={n: why for n, why in frozen.items() if n not in order},
        iterations=iterations,
        solver_status=status,
        message=message,
        history=tuple(float(h) for h in history),
        weights=weights,
        start_analysis=start_analysis,
        end_analysis=end_analysis,
        start_robot=start,
        rounds=rounds,
        settled=settled,
        joined=tuple(n for n in order if n not in start_analysis.base_parameters),
    )


FROZEN = "blind where the fit ended; held at the value it was fitted to while visible"

WORKSPACE_POSES = 200


def _held_that_matter(linear, names, order, pruned, settings) -> list[str]:
    """The parameters held as useless, if freeing them would gain more than chance."""
    useless = [n for n, why in pruned.items() if WIDE not in why and n in names]
    if not useless:
        return []
    gain = held_gain(linear, names, order, useless)
    matter = held_matter(
        gain, len(useless), 0.5 * linear.rr, linear.rows - len(order), settings.known
    )
    return [n for n in names if n in useless] if matter[0] else []


def _release(make, point, names, settings, weights, hold, order, base, r):
    """Parameters estimated so far that are blind where the fit ended: back to their start
    values when that costs nothing (a wrist angle about which the tool point turns in
    place), else kept at their fitted values (returned as `lost`, to be reported)."""
    blind = [n for n in order if n not in base]
    if not blind:
        return point, []
    reset = point.with_parameters({n: hold[n] for n in blind})
    problem = _problem(make, reset, names, settings, weights)
    r_reset = problem.residual(np.zeros(len(names)))
    if r_reset @ r_reset <= (r @ r) * (1 + 1e-9) + 2 * floor_cost(problem):
        return reset, []
    return point, blind


def measured_weights(w: np.ndarray) -> np.ndarray:
    """The weights `w` of measured coordinates: all of them (the same array) unless some
    are 0 (σ inf, not measured), which say nothing of the noise."""
    return w if np.all(w > 0) else w[w > 0]


def workspace_poses(robot: Robot):
    """Poses spread within the joint limits (fixed seed), or None without limits."""
    try:
        return uniform(robot, WORKSPACE_POSES, seed=0)
    except CalibrationError:
        return None


def check_analysis(full: Problem) -> Observability:
    """Identifiability at `full`'s robot, refusing data that cannot decide it."""
    names = full.names
    obs = analyse(full.reduced(np.zeros(len(names))).R, names, full.q.shape[0])
    n_poses, rows = full.q.shape[0], full.observed_rows
    if obs.rank >= rows and len(names) > obs.rank:
        # the data, not the robot's structure, limit what can be seen
        give = "poses give" if n_poses != 1 else "pose gives"
        raise CalibrationError(
            f"{n_poses} {give} {rows} coordinates, fewer than the "
            f"{len(names)} parameters asked for, so they cannot tell which are blind; "
            f"measure at least {math.ceil((len(names) + 1) / (rows / n_poses))} poses "
            f"({rows / n_poses:.3g} coordinate{'s' * (rows != n_poses)} a pose) or ask for "
            "fewer parameters"
        )
    if not obs.base_parameters:
        raise CalibrationError(
            f"none of the asked-for parameters ({', '.join(names)}) moves the measured point at "
            "these poses; ask for others or measure other poses"
        )
    return obs


def _problem(make, point, names, settings: Settings, weights, kernel_names=None) -> Problem:
    problem = make(point, names=names, kernel_names=kernel_names)
    return problem if settings.loss == "linear" else problem.reweighted(weights)


def _solve_round(make, point, names, estimated, settings: Settings, weights, hold, rnd=1):
    """One round: the solver (inside iteratively reweighted least squares for a robust
    loss) on the `estimated` parameters from `point`."""
    solver = SOLVERS[settings.method]
    kwargs = {"max_iterations": settings.max_iterations, "tolerance": settings.tolerance}
    if settings.progress is not None:
        # cost → RMS per measured coordinate, in σ (or m) units
        rows = int(np.count_nonzero(make(point, names=names).w_flat))
        # weighted residuals are in σ; back to mm with the RMS σ (1 without σ: in m)
        scale = 1e3 * float(np.sqrt(np.mean(1.0 / measured_weights(settings.w) ** 2)))

        def report(it: int, cost: float) -> None:
            rms = scale * np.sqrt(2.0 * cost / rows)
            settings.progress(f"round {rnd}, iteration {it}: RMS {rms:.4g} mm per coordinate")

        kwargs["callback"] = report
    if settings.method == "ipopt":
        # bounds and prior are on deviations from nominal; x is from the current point
        offset = deviations_between(hold, point.parameters, estimated)
        kwargs["bounds"] = {
            n: (lo - offset[n], hi - offset[n])
            for n, (lo, hi) in settings.bounds.items()
            if n in estimated
        }
        kwargs["prior"] = {n: sd for n, sd in settings.prior.items() if n in estimated}
        kwargs["prior_offset"] = np.array([offset[n] for n in estimated])
    iterations, history = 0, []
    rejected = False
    for _ in range(1 if settings.loss == "linear" else 21):
        problem = _problem(make, point, names, settings, weights).restricted(estimated)
        x = np.zeros(len(estimated))
        r = problem.residual(x)
        start_cost = 0.5 * float(r @ r)
        del r  # the solver evaluates it again (memoised); N rows not kept through its run
        if start_cost <= floor_cost(problem):  # nothing left to fit (a later round)
            return point, iterations, 4, history or [start_cost], None, weights
        x, its, status, hist, message = solver(problem, x, **kwargs)
        if settings.method == "gauss-newton" and status in (0, 3) and settings.damped_after_stall:
            # stalled in a curved valley: Levenberg-Marquardt's damping goes on from here
            x, more, status, tail, message = SOLVERS["lm"](problem, x, **kwargs)
            its, hist = its + more, hist + tail[1:]
        iterations += its
        history += hist if not history else hist[1:]
        point = point.with_deviations(dict(zip(estimated, x.tolist(), strict=True)))
        if settings.loss == "linear" or status < 0 or rejected:
            break
        at = make(point, names=names)
        residuals = at.point_residuals(np.zeros(len(names)))
        e = np.linalg.norm(residuals * settings.w[:, None, :], axis=2)  # (N, m), σ units
        c = settings.loss_scale * (1.0 if settings.known else _robust_sd(e))
        new = _loss_weights(settings.loss, e, c)
        if np.abs(new - weights).max() < 1e-6:
            # the loss found the outliers; least squares on the rest gives estimates whose
            # covariance and χ² hold (a bounded influence is still a bias)
            new = np.ones_like(weights)
            new[list(outlier_poses(at, settings.w, settings.known))] = 0.0
            rejected = True
        weights = new
    return point, iterations, status, history, message, weights


def _loss_weights(loss: str, e: np.ndarray, c: float) -> np.ndarray:
    """IRLS weights of residual norms `e` for a robust loss of scale `c`."""
    if loss == "huber":
        return np.where(e <= c, 1.0, c / np.maximum(e, 1e-300))
    return 1.0 / np.sqrt(1.0 + (e / c) ** 2)


def _robust_sd(e: np.ndarray) -> float:
    """Standard deviation of one coordinate from the median of point-residual norms.

    For Gaussian noise the norm of a 3-vector has median ≈ 1.538 σ.
    """
    return float(np.median(e)) / 1.538 or 1e-12


def workspace_jacobian(point: Robot, q_work, names, full: Problem) -> np.ndarray:
    """Unweighted Jacobian of the measured points at workspace poses, (3 n, k), m/unit.

    At `q_work` (poses spread within the joint limits) when there are any, else at up to
    `WORKSPACE_POSES` of the measured poses, evenly spread through the data.
    """
    if q_work is None:
        n = len(full.q)
        q_work = full.q[np.unique(np.linspace(0, n - 1, min(n, WORKSPACE_POSES)).astype(int))]
    chain = full.chain
    p = point.vector()  # anchored: columns in the deviations, as the fit's (Problem.p)
    J = chain.evaluate("points_jacobian", q_work, p, full.kernel_columns, anchor=p)
    return J.reshape(-1, J.shape[-1])[:, full.take]
