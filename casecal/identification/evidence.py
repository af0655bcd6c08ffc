"""What the data say about parameters the fit did not estimate, for the answer audit.

Three kinds of parameter sit outside a fit's estimated set, and each can hide a wrong robot
behind residuals that look like noise:

- *held for the noise* (`casecal.identification.rank`): tested by the gain of freeing
  them (`casecal.identification.rank.held_gain`);
- *blind here*: parameters the measured poses cannot tell from others, although poses
  across the joint ranges would (every pose at q5 = 0, a joint that never moves, the
  paper's lockstep schedule). The estimates beside them absorb their deviations, which
  holds only on poses like the measured ones: `blind_only_here`;
- *not asked for*: the robot's parameters outside the asked-for set (α when the paper's
  θ, a, d were asked, the base frame when it was not): `outside_gain` measures what
  freeing them would explain.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.robot import Robot
from .analysis import analyse
from .problem import Problem
from .rounds import workspace_jacobian, workspace_poses

STILL = {"R": np.radians(1.0), "P": 1e-3}
"""A joint whose values span less than this (1°, 1 mm) in the data barely moves."""


def blind_only_here(
    problem: Problem, robot: Robot, estimated, held_for_noise, free=()
) -> tuple[str, ...]:
    """Parameters blind at the measured poses that poses across the joint ranges would see.

    Parameters
    ----------
    problem : Problem
        The measurements, with every asked-for parameter (its kernel is what is used).
    robot : Robot
        Where the estimated set was chosen (the fitted robot; for the one-shot method, where
        it linearised).
    estimated, held_for_noise : sequence of str
        The estimated parameters, and those held because the noise hides them (tested
        elsewhere).
    free : sequence of str
        Parameters outside `problem.names` (in its kernel) that poses across the joint
        ranges would estimate too: a contact session's frame parameters the data cannot
        see, when it is the first session, whose frame is the robot's base (what only
        moves the whole robot is no more seen across the joint ranges than here).
    """
    if free:
        names = list(problem.names)
        problem = problem.restricted([*names, *free])
        held = [n for n in names if n not in estimated and n not in held_for_noise]
        q_work = workspace_poses(robot)
        if q_work is None or not held:
            return ()
        J = workspace_jacobian(robot, q_work, problem.names, problem)
        prefer = [*free, *estimated]
        elsewhere = analyse(J, problem.names, q_work.shape[0], prefer=prefer).base_parameters
        return tuple(n for n in held if n in elsewhere)
    names = list(problem.names)
    q_work = workspace_poses(robot)
    held = [n for n in names if n not in estimated and n not in held_for_noise]
    if q_work is None or not held:
        return ()
    J = workspace_jacobian(robot, q_work, names, problem)  # at `robot`'s parameters
    elsewhere = analyse(J, names, q_work.shape[0], prefer=list(estimated)).base_parameters
    return tuple(n for n in held if n in elsewhere)


def gauge_bound(problem: Problem, robot: Robot, estimated, free, candidates) -> tuple[str, ...]:
    """Those of `candidates` that, across the joint ranges, only move the robot as a
    whole once the `free` frame parameters are free (as a contact session's first frame
    is, which its data cannot see): no error of theirs shows anywhere, so there is
    nothing for the data to determine (`blind_only_here`'s `free`)."""
    q_work = workspace_poses(robot)
    if q_work is None or not free or not candidates:
        return ()
    names = [*problem.names, *(n for n in free if n not in problem.names)]
    wide = problem.restricted(names)
    J = workspace_jacobian(robot, q_work, names, wide)
    prefer = [*free, *estimated]
    seen = analyse(J, names, q_work.shape[0], prefer=prefer).base_parameters
    return tuple(n for n in candidates if n not in seen)


def still_joints(q: np.ndarray, robot: Robot) -> tuple[str, ...]:
    """Joints that barely move in the data (`STILL`), e.g. ``("q5 = 0.000°",)``."""
    still = []
    for i, kind in enumerate(robot.controller_types):  # the columns `q` has
        if np.ptp(q[:, i]) < STILL[kind]:
            value = np.degrees(q[0, i]) if kind == "R" else q[0, i] * 1e3
            still.append(f"q{i + 1} = {value:.3f}{'°' if kind == 'R' else ' mm'}")
    return tuple(still)


@dataclass(frozen=True)
class Outside:
    """What freeing the parameters outside the asked-for set would explain.

    Attributes
    ----------
    gain : float
        Decrease of the cost (one linearised step), in the cost's units.
    n_visible : int
        How many independent directions they add to the estimated set: the degrees of
        freedom of the gain.
    leading : tuple of str
        Those whose own gain is largest, largest first (at most four).
    """

    gain: float = 0.0
    n_visible: int = 0
    leading: tuple[str, ...] = ()


def outside_gain(problem: Problem, estimated) -> Outside:
    """`Outside` of `problem`, at its robot.

    Parameters
    ----------
    problem : Problem
        The measurements at the fitted robot (weighted as in the fit), whose names are the
        `estimated` parameters followed by those not asked for.
    estimated : sequence of str
        The estimated parameters.
    """
    names = list(problem.names)
    linear = problem.reduced(np.zeros(len(names)))
    est = [names.index(n) for n in estimated]
    base = analyse(linear.R, names, problem.q.shape[0], prefer=list(estimated)).base_parameters
    extra = [names.index(n) for n in base if n not in estimated]
    if not extra:
        return Outside()

    inside = linear.columns(est).solve()[1] if est else 0.0
    gain = linear.columns(est + extra).solve()[1] - inside
    alone = {names[k]: linear.columns([*est, k]).solve()[1] - inside for k in extra}
    leading = sorted(alone, key=alone.get, reverse=True)[:4]
    return Outside(max(gain, 0.0), len(extra), tuple(leading))
