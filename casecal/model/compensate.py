"""Compensated joint targets: how to apply a calibration to a controller that takes no new
parameters.

The controller believes the nominal robot: sent joint values q_t, it expects the tool at
the nominal robot's pose at q_t. The real robot (the calibrated model) puts it elsewhere.
Sending the joint values q at which the calibrated robot reaches that pose puts the tool
where the controller meant. What "that pose" is depends on the frame the targets live in
(`compensate`'s ``frame``):

- ``"robot"``: the robot's own base frame. Where a calibration puts the base frame and
  where the first joints is a blind split (a turn of joint 1 and a turn of the base look
  alike to any instrument), so the base frame is defined by the robot itself: the nominal
  robot placed where it best fits the calibrated one (`registration`). The answer does
  not depend on how the calibration split a blind combination.
- ``"instrument"``: the frame the calibration was measured in, for a user who knows where
  the base stands in it (the nominal robot's base frame says so): the calibrated robot,
  with its fitted base, must reach the nominal robot's pose.

The search itself (`casecal.model.compensate_solve`) starts at the targets' joint values and
takes the smallest joint change; a row whose change is far larger than the pose difference
can justify (near a singularity) is refused with the joint and the numbers.

A kinematic tree (several tips) is compensated the same way, every tip at once: per pose
one search over all its joints, each tip to the nominal tree's pose of it
(`casecal.model.compensate_tree`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import CalibrationError
from .compensate_solve import (
    AMPLIFICATION,
    REACHED,
    aligned_axes,
    error_norms,
    matches_orientation,
    pose_errors,
    solve,
)
from .compensate_tree import check_same_tips, tree_rows
from .frames import rigid_fit
from .robot import Robot, check_joint_values

FRAMES = ("robot", "instrument")
REGISTRATION_POSES = 200
"""Poses, uniform in the nominal robot's joint ranges (seed 0), that `registration` fits."""
NEAR = AMPLIFICATION
"""Condition number of the scaled joint Jacobian above which a failure is said to be near
a singularity (random poses of six-axis arms: half of them under 10)."""
GROSS = 0.05
"""m: nominal and calibrated tool points farther apart than this (RMS) are not one robot
with calibration errors."""


@dataclass(frozen=True)
class Compensation:
    """Corrected joint values and, per row, whether they can be used.

    Attributes
    ----------
    q : ndarray, shape (N, dof)
        Joint values to send (the controller's joints), rad (R) or m (P); the target
        itself on rows that failed.
    ok : ndarray of bool, shape (N,)
        Converged to the target, not near a singularity (the correction is no larger than
        the pose difference justifies) and within the joint limits.
    position_error, orientation_error : ndarray, shape (N,)
        Where the calibrated robot's tool ends at the returned values, against the target,
        m and rad (0 where only the position is matched: fewer than six joints, or
        ``orientation=False``); on a failed row, the error the uncorrected target leaves.
        A tree's: the largest over its tips (orientation over the tips whose orientation
        is matched, `casecal.model.compensate_tree.tree_rows`).
    reason : tuple of str
        Per row: "" when `ok`, else why not, in words and numbers ("near a singularity
        (axes of joints 4 and 6 0.4° apart): the correction would turn joint 4 by 41°
        ...", "at a singularity", "no convergence", "out of reach", "outside the limits
        of joint k").
    frame : str
        "robot" or "instrument" (see `compensate`).
    registration : ndarray, shape (4, 4)
        The nominal robot's world frame in the calibrated robot's: for ``frame="robot"``
        the best fit (see `registration`), for ``"instrument"`` the identity.
    """

    q: np.ndarray
    ok: np.ndarray
    position_error: np.ndarray
    orientation_error: np.ndarray
    reason: tuple[str, ...]
    frame: str = "robot"
    registration: np.ndarray | None = None


def registration_poses(nominal: Robot) -> np.ndarray:
    """The poses `registration` fits: `REGISTRATION_POSES` uniform in the nominal robot's
    joint ranges (±180° for a revolute joint without limits), seed 0; (n, dof), rad or m."""
    try:
        limits = nominal.limits
    except CalibrationError as exc:
        raise CalibrationError(
            f"{exc}: compensation aligns the nominal robot to the calibrated one over poses "
            "across the joint ranges (to place the robot's frame, and to check they are one "
            "robot)"
        ) from None
    rng = np.random.default_rng(0)
    return rng.uniform(limits[:, 0], limits[:, 1], size=(REGISTRATION_POSES, nominal.dof))


def registration(nominal: Robot, calibrated: Robot) -> tuple[np.ndarray, float, float]:
    """The rigid transform that best aligns the nominal robot's tool points to the
    calibrated robot's over `registration_poses` (least squares).

    The calibrated robot's tool points, its base frame times its chain, do not depend on
    how the fit split a blind combination between the base and the joints, so neither
    does this transform.

    Returns
    -------
    X : ndarray, shape (4, 4)
        Nominal world frame to calibrated world frame, m.
    before, after : float
        RMS distance of the tool points without and with X, m.
    """
    q = registration_poses(nominal)
    # a tree's tips' points, all in one fit
    p_nominal = nominal.position(q).reshape(-1, 3)
    p_calibrated = calibrated.position(q).reshape(-1, 3)
    R, t = rigid_fit(p_nominal, p_calibrated)
    X = np.eye(4)
    X[:3, :3], X[:3, 3] = R, t
    rms = lambda d: float(np.sqrt(np.mean(np.sum(d**2, axis=1))))  # noqa: E731
    return X, rms(p_calibrated - p_nominal), rms(p_calibrated - p_nominal @ R.T - t)


def compensate(
    calibrated: Robot,
    q_targets,
    nominal: Robot | None = None,
    max_iterations: int = 30,
    frame: str = "robot",
    orientation: bool | None = None,
) -> Compensation:
    """Joint values that bring `calibrated` to where `nominal` would be at `q_targets`.

    Parameters
    ----------
    calibrated : Robot
        The real robot, as identified (with its fitted base frame), error terms included
        (its compliance's deflections at the returned joints are part of where it goes);
        a tree brings every tip to the nominal tree's pose of it.
    q_targets : array-like, shape (N, dof) or (dof,)
        The joint values the program sends today, rad (R) or m (P).
    nominal : Robot, optional
        The robot the controller believes; default the one `calibrated` was calibrated
        from (its ``calibrated_from``).
    max_iterations : int
    frame : {"robot", "instrument"}
        What the target is. ``"robot"`` (default): the nominal robot's tool pose at
        `q_targets` in the robot's base frame as the controller defines it, i.e. the
        nominal robot placed where it best fits the calibrated one (`registration`:
        least squares over the tool points of 200 poses across the joint ranges, seed 0).
        A base-like error (joint 1's zero, its height) is then part of the base frame and
        left alone, whichever way the calibration split it between base and joints.
        ``"instrument"``: the nominal robot's tool pose, with the nominal robot's own base
        frame, in the frame the calibration was measured in; for a user who measured where
        the base stands (or a simulation). Every error, base-like ones included, is then
        corrected.
    orientation : bool, optional
        Match the tool's orientation as well as its position; default: for arms of six
        or more joints; on a tree, per tip, for tips six or more joints move
        (`casecal.model.compensate_tree.tree_rows`). Give False for a calibration from
        positions alone, whose tool orientation may be blind (Notes): the position is then
        matched with the least joint motion, and the orientation is left as the joints put
        it.

    Returns
    -------
    Compensation

    Notes
    -----
    Arms of six or more joints match the full tool pose (unless ``orientation=False``),
    fewer the position. Positions
    are as good as the calibration; orientations only where its data could see them. From
    positions of one point per pose the tool's turn about that point is blind (a turn of
    the last joint about an axis through it, a last joint and the tool offset turned
    against each other, the tool frame's own angles): the fit keeps such a combination at
    one value of its choice, the real tool may stand turned by the unknown rest at the
    returned joint values, and two fits that chose differently return different joints;
    the position reached is the same. Measured orientations (or several points per pose)
    make the orientation as good as the position.

    Raises
    ------
    CalibrationError
        No nominal robot, joint counts or tips that differ, an unknown frame, or nominal and
        calibrated robots more than 50 mm apart (RMS over the poses): another robot,
        another tool, or for ``"instrument"`` a nominal base frame that is not where the
        instrument saw the robot.
    """
    if frame not in FRAMES:
        raise CalibrationError(
            f"unknown compensation frame {frame!r}; use 'robot' (targets in the robot's base "
            "frame, the default) or 'instrument' (in the frame the calibration was measured "
            "in); frame= in Python, --frame on the command line"
        )
    nominal = _nominal(calibrated, nominal)
    q_t, _ = check_joint_values(q_targets, calibrated.dof)
    X, before, after = registration(nominal, calibrated)
    _check_same_robot(frame, before, after)
    if frame == "instrument":
        X = np.eye(4)
    target = X @ nominal.fk(q_t)  # a tree's: (N, tips, 4, 4)
    rows = _rows(calibrated, orientation)
    found = solve(calibrated, q_t, target, rows, max_iterations, scale=nominal)
    ok, reason = _judge(calibrated, q_t, found, rows)
    q = np.where(ok[:, None], found.q, q_t)
    e = pose_errors(calibrated, q, target)  # where the returned values put the tool
    position_error, orientation_error = error_norms(e, rows)
    return Compensation(
        q=q,
        ok=ok,
        position_error=position_error,
        orientation_error=orientation_error,
        reason=tuple(reason),
        frame=frame,
        registration=X,
    )


def _rows(calibrated: Robot, orientation: bool | None):
    """The pose error rows to match (`solve`): a slice of the six, a tree's indices."""
    if calibrated.is_tree:
        return tree_rows(calibrated, orientation)
    if orientation is None:
        orientation = calibrated.dof >= 6
    if orientation and calibrated.dof < 6:
        raise CalibrationError(
            f"robot {calibrated.name!r} has {calibrated.dof} joints: too few to set the "
            "tool's orientation as well as its position; match the position only"
        )
    return slice(None) if orientation else slice(0, 3)


def _nominal(calibrated: Robot, nominal: Robot | None) -> Robot:
    if nominal is None:
        if not calibrated.calibrated_from:
            raise CalibrationError(
                "compensate needs the nominal robot (the one the controller believes): give "
                "it with --nominal ROBOT on the command line, nominal= in Python, or use a "
                "robot file written by identify (it records calibrated_from)"
            )
        from .catalog import nominal_of

        nominal = nominal_of(calibrated)
    check_same_tips(nominal, calibrated)
    if nominal.dof != calibrated.dof:
        raise CalibrationError(
            f"the nominal robot has {nominal.dof} joints, the calibrated one {calibrated.dof}"
        )
    if nominal.coupling != calibrated.coupling:
        # the same joint values would mean other model joints to each: no target is shared
        raise CalibrationError(
            "the nominal and calibrated robots couple their joints differently "
            f"({_coupling_words(nominal)} against {_coupling_words(calibrated)}); give the "
            "nominal robot the calibrated one's coupling (Robot.with_coupling, [coupling])"
        )
    return nominal


def _coupling_words(robot: Robot) -> str:
    if robot.coupling is None:
        return "none"
    return "; ".join(robot.coupling.describe(robot.joint_types)) or "identity"


def _check_same_robot(frame: str, before: float, after: float) -> None:
    if after > GROSS:
        raise CalibrationError(
            f"the nominal and calibrated robots' tool points are {after * 1e3:.3g} mm apart "
            "(RMS over poses across the joint ranges, after the best rigid alignment): more "
            "than calibration errors; is the nominal robot (nominal=, --nominal) the one this "
            "was calibrated from, with the same tool?"
        )
    if frame == "instrument" and before > GROSS:
        raise CalibrationError(
            f"frame='instrument' (--frame instrument): the nominal robot's tool points are "
            f"{before * 1e3:.4g} mm (RMS) from where the calibration puts the robot in the "
            "instrument's frame; give the nominal robot the base frame measured in the "
            "instrument's frame, or use frame='robot' (--frame robot, the default: targets "
            "in the robot's base frame)"
        )


def _judge(robot: Robot, q_t: np.ndarray, found, rows: slice) -> tuple[np.ndarray, list[str]]:
    """Per row: usable, and if not, why (words and numbers)."""
    q = found.q
    # a joint without limits (continuous) turns freely: its default range is for sampling
    joints = robot.controller_joints  # what the controller is sent
    lo = np.array([-np.inf if j.limits is None else j.limits[0] for j in joints])
    hi = np.array([np.inf if j.limits is None else j.limits[1] for j in joints])
    outside = (q < lo - 1e-12) | (q > hi + 1e-12)
    too_far = found.amplification > AMPLIFICATION
    ok = (
        found.converged
        & ~found.singular
        & (found.miss <= REACHED)
        & ~too_far
        & ~outside.any(axis=1)
    )
    position_only = not matches_orientation(rows)
    off = "mm off" if position_only else "mm or mrad off"
    tool = "tips up to" if robot.is_tree else "tool"
    reason = [""] * len(q)
    for k in np.flatnonzero(~ok):  # words only for the rows that need them
        dp, dphi = found.difference[k]
        difference = f"{dp * 1e3:.3g} mm" + ("" if position_only else f" and {dphi * 1e3:.3g} mrad")
        if found.singular[k]:
            reason[k] = (
                "at a singularity: the joints cannot move the tool in every direction here "
                f"(condition number {found.condition[k]:.2g})"
            )
        elif not found.converged[k] or found.miss[k] > REACHED:
            words = "not reached" if not found.converged[k] else "out of reach"
            if found.condition[k] > NEAR:
                words += f" near a singularity (condition number {found.condition[k]:.3g})"
            reason[k] = (
                f"{words}: the nearest joint values found leave the {tool} "
                f"{found.miss[k] * 1e3:.3g} {off}"
            )
        elif too_far[k]:
            reason[k] = _near_singular(robot, q_t[k], q[k] - q_t[k], difference)
        else:
            j = int(np.argmax(outside[k]))
            limit = lo[j] if q[k, j] < lo[j] else hi[j]
            reason[k] = (
                f"outside the limits of joint {j + 1}: the correction would take it to "
                f"{_amount(robot, j, q[k, j])}, beyond its limit {_amount(robot, j, limit)}"
            )
    return ok, reason


def _amount(robot: Robot, j: int, value: float) -> str:
    if robot.controller_joints[j].type == "R":
        return f"{np.rad2deg(value):.3g}°"
    return f"{value * 1e3:.4g} mm"


def _near_singular(robot: Robot, q: np.ndarray, dq: np.ndarray, difference: str) -> str:
    axes = aligned_axes(robot, q)
    where = (
        f" (axes of joints {axes[0]} and {axes[1]} {np.rad2deg(axes[2]):.2g}° apart)"
        if axes
        else ""
    )
    j = int(np.argmax(np.abs(dq)))
    verb = "turn" if robot.controller_joints[j].type == "R" else "move"
    return (
        f"near a singularity{where}: the correction would {verb} joint {j + 1} by "
        f"{_amount(robot, j, dq[j])} for a pose difference of {difference}; a correction "
        "that large is not one calibration errors justify"
    )
