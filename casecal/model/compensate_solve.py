"""The joint search behind `casecal.model.compensate`: the smallest joint change that brings
a robot's tool to given poses, and whether that change is one a calibration can justify.

A calibration corrects errors of millimetres and milliradians; the joint change that undoes
them is of the same size divided by the joints' levers. Near a singularity the same pose
difference needs joint changes that grow without bound (at a wrist singularity, joints 4
and 6 turning tens of degrees against each other for a fraction of a milliradian): the
tool gets there, but by a motion nobody asked for. Such rows are refused, with the joint
and the numbers.

Sizes are compared in one unit: a joint's change times its lever (the norm of its column
of the joint Jacobian, a radian of orientation counted as the robot's characteristic
length, half its reach) against the pose difference weighed the same way. A wrist joint
then has a lever of about that length whatever the tool point's distance from its axis, so
that turning it by 40° is never justified by millimetres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import kinematics
from .frames import rotation_vector
from .robot import Robot

TOLERANCE = 1e-12  # m and rad: a step or an error this small has converged
SINGULAR = 1e-9  # smallest over largest singular value of the scaled joint Jacobian
REACHED = 1e-9  # m and rad: a row whose tool ends farther off than this has failed
AMPLIFICATION = 30.0
"""Largest joint change (times its lever) per unit of pose difference a row may need.

Random poses of six-axis catalog arms need 3 to 5 (median) and 11 to 29 (90th percentile);
within a degree of a wrist singularity, hundreds."""
DAMPING = 1e-9  # λ² relative to trace(A Aᵀ): keeps steps finite at a singularity


@dataclass(frozen=True)
class Solution:
    """What `solve` found, per row (N rows).

    Attributes
    ----------
    q : ndarray, shape (N, dof)
        Where the search ended, rad or m.
    converged : ndarray of bool, shape (N,)
    miss : ndarray, shape (N,)
        Largest remaining error component at `q`, m or rad.
    singular : ndarray of bool, shape (N,)
        The scaled joint Jacobian at the target has (numerically) lost rank.
    condition : ndarray, shape (N,)
        Its largest over smallest singular value at the target.
    amplification : ndarray, shape (N,)
        Joint change times lever over pose difference (both in m, see the module).
    difference : ndarray, shape (N, 2)
        Pose difference at the target before correction: position m, orientation rad.
    """

    q: np.ndarray
    converged: np.ndarray
    miss: np.ndarray
    singular: np.ndarray
    condition: np.ndarray
    amplification: np.ndarray
    difference: np.ndarray


def pose_errors(robot: Robot, q: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Target minus the robot's tool pose: (N, 6), position m then rotation vector rad; a
    tree's tips one after the other, (N, 6 · tips), `target` then (N, tips, 4, 4)."""
    T = robot.fk(q)
    rot = rotation_vector(target[..., :3, :3] @ np.swapaxes(T[..., :3, :3], -1, -2))
    e = np.concatenate([target[..., :3, 3] - T[..., :3, 3], rot], axis=-1)
    return e.reshape(len(q), -1)


def error_norms(e: np.ndarray, rows) -> tuple[np.ndarray, np.ndarray]:
    """Position and orientation errors per pose from pose errors `e` (N, 6 · tips), m and
    rad: each tip's norms, the largest over the tips; orientation 0 for a tip whose rotation
    rows are not among the matched `rows` (a slice or indices)."""
    matched = np.zeros(e.shape[1], dtype=bool)
    matched[rows] = True
    e3, m3 = e.reshape(len(e), -1, 6), matched.reshape(-1, 6)
    position = np.linalg.norm(e3[..., :3], axis=2).max(axis=1)
    rotation = np.linalg.norm(np.where(m3[None, :, 3:], e3[..., 3:], 0.0), axis=2).max(axis=1)
    return position, rotation


def matches_orientation(rows) -> bool:
    """Whether `rows` (a slice of the six, or a tree's indices) match any orientation."""
    if isinstance(rows, slice):
        return rows == slice(None)
    return bool(np.any(np.asarray(rows) % 6 >= 3))


def characteristic_length(robot: Robot) -> float:
    """m per rad: how much tool motion a radian counts as, half the robot's reach (1 m
    when the reach is unbounded), so that joint changes and pose differences compare in
    one unit whatever the robot's size."""
    reach = robot.reach
    return 0.5 * reach if reach else 1.0


def _weights(rows, length: float, tips: int = 1) -> np.ndarray:
    """Per row of `rows` (a slice or indices of the six rows per tip), m per its unit."""
    return np.tile([1.0, 1.0, 1.0, length, length, length], tips)[rows]


def difference_norms(e: np.ndarray) -> np.ndarray:
    """(N, 2): the norm of the position rows and of the orientation rows of pose errors `e`
    (N, 6 · tips) from `pose_errors`, m and rad, over every tip."""
    e = e.reshape(len(e), -1, 6)
    return np.stack(
        [np.linalg.norm(e[..., :3], axis=(1, 2)), np.linalg.norm(e[..., 3:], axis=(1, 2))], axis=1
    )


def joint_jacobian(robot: Robot, q: np.ndarray, rows: slice) -> np.ndarray:
    """∂(position m, orientation rad)/∂q in the robot's world frame, (N, len(rows), dof),
    `rows` of the six (a tree's: of its 6 · tips, tip after tip); q and the columns are
    the controller's joints (the model's Jacobian times the coupling's M)."""
    chain = kinematics.chain(robot.structure)
    J = chain.evaluate("joint_jacobian", robot.model_joints(q), robot.vector())[:, rows, :]
    return J if robot.coupling is None else J @ robot.coupling.M


def levers(J: np.ndarray, length: float) -> np.ndarray:
    """Per row and joint, how far a unit change of the joint moves the tool, (N, dof), m:
    the norm of its column of the full joint Jacobian `J` (N, 6, dof), a radian of
    orientation counted as `length`. Weighed so even where only the position is matched:
    turning a joint a radian is a large motion whether or not the matched point moves."""
    w = _weights(slice(None), length, J.shape[1] // 6)
    ell = np.linalg.norm(J * w[None, :, None], axis=1)
    return np.maximum(ell, 1e-300)


def solve(
    robot: Robot,
    q_start: np.ndarray,
    target: np.ndarray,
    rows: slice,
    max_iterations: int,
    scale: Robot | None = None,
) -> Solution:
    """Joint values near `q_start` that bring `robot`'s tool to `target`.

    Gauss-Newton in scaled joints (each joint's change times its lever), with the
    minimum-norm step where the joints are redundant, a tiny Tikhonov damping that keeps
    steps finite at a singularity, and halving of a step that does not lower the error.

    Parameters
    ----------
    robot : Robot
        The robot that must reach the targets, with its base frame.
    q_start : ndarray, shape (N, dof)
        Where each search starts (the targets' joint values), rad or m.
    target : ndarray, shape (N, 4, 4)
        Tool poses in `robot`'s world frame, m.
    rows : slice or ndarray of int
        Which of (x, y, z, rx, ry, rz) must match: all six, or the position; a tree's: the
        indices of the rows to match among its 6 · tips (`pose_errors`).
    max_iterations : int
    scale : Robot, optional
        The robot whose levers and size scale the joints (default `robot`). The nominal
        robot: then the metric, and with it the minimum-norm answer of a redundant arm,
        does not depend on parameters the calibration could not see.

    Returns
    -------
    Solution
    """
    scale = robot if scale is None else scale
    length = characteristic_length(scale)
    w = _weights(rows, length, len(robot.tips) if robot.is_tree else 1)
    ell = levers(joint_jacobian(scale, q_start, slice(None)), length)
    J0 = joint_jacobian(robot, q_start, rows)
    A0 = J0 * w[None, :, None] / ell[:, None, :]
    s0 = np.linalg.svd(A0, compute_uv=False)
    singular = s0[:, -1] <= SINGULAR * s0[:, 0]
    condition = s0[:, 0] / np.maximum(s0[:, -1], 1e-300)
    e = pose_errors(robot, q_start, target)
    difference = difference_norms(e)
    e = e[:, rows]
    cost = np.sum((e * w) ** 2, axis=1)
    first = np.sqrt(cost)
    q = q_start.copy()
    converged = np.max(np.abs(e), axis=1) < TOLERANCE
    active = ~converged
    for _ in range(max_iterations):
        if not active.any():
            break
        k = np.flatnonzero(active)
        J = joint_jacobian(robot, q[k], rows)
        A = J * w[None, :, None] / ell[k][:, None, :]
        # minimum-norm damped step: Aᵀ (A Aᵀ + λ² I)⁻¹ e, whatever the joint count
        AAt = A @ np.transpose(A, (0, 2, 1))
        lam = DAMPING * np.trace(AAt, axis1=1, axis2=2) + 1e-30
        AAt = AAt + lam[:, None, None] * np.eye(AAt.shape[1])
        y = np.linalg.solve(AAt, (e[k] * w)[..., None])[..., 0]
        step = np.einsum("nji,nj->ni", A, y) / ell[k]
        # halve a step that does not lower the error; a row that cannot lower it has stalled
        for _halving in range(12):
            q_try = q[k] + step
            e_try = pose_errors(robot, q_try, target[k])[:, rows]
            cost_try = np.sum((e_try * w) ** 2, axis=1)
            worse = cost_try > cost[k] * (1 + 1e-12) + 1e-30
            if not worse.any():
                break
            step = np.where(worse[:, None], step / 2, step)
        take = ~worse
        q[k[take]], e[k[take]], cost[k[take]] = q_try[take], e_try[take], cost_try[take]
        done = take & (
            (np.max(np.abs(step), axis=1) < TOLERANCE) | (np.max(np.abs(e_try), axis=1) < TOLERANCE)
        )
        converged[k] = done
        # a search that has turned a joint a full turn away is lost, not converging
        lost = np.max(np.abs(q[k] - q_start[k]), axis=1) > 2 * np.pi
        active[k] = ~done & take & ~lost
    miss = np.max(np.abs(e), axis=1)
    moved = np.linalg.norm((q - q_start) * ell, axis=1)
    amplification = np.where(first > 1e-15, moved / np.maximum(first, 1e-300), 0.0)
    return Solution(q, converged, miss, singular, condition, amplification, difference)


def aligned_axes(robot: Robot, q: np.ndarray) -> tuple[int, int, float] | None:
    """The two revolute joints whose axes most nearly coincide at pose `q` (dof,), as
    (i, j, angle rad), 1-based; None when no two axes are within 10° and 10 mm of a
    common line (what a wrist singularity looks like), for a coupled robot, whose
    controller joints need not turn about one axis each, and for a tree (several tips)."""
    if robot.coupling is not None or robot.is_tree:
        return None
    J = joint_jacobian(robot, q[None, :], slice(None))[0]
    p = robot.fk(q)[:3, 3]
    best = None
    revolute = [i for i, t in enumerate(robot.joint_types) if t == "R"]
    for a in revolute:
        for b in revolute:
            if b <= a:
                continue
            wa, wb = J[3:, a], J[3:, b]
            if np.linalg.norm(wa) < 0.5 or np.linalg.norm(wb) < 0.5:
                continue
            angle = float(np.arccos(min(1.0, abs(float(wa @ wb)))))
            # the axis through o: v = ω × (p - o), so p + ω × v lies on it
            oa, ob = p + np.cross(wa, J[:3, a]), p + np.cross(wb, J[:3, b])
            gap = float(np.linalg.norm(np.cross(ob - oa, wa)))
            if angle < np.deg2rad(10) and gap < 0.01 and (best is None or angle < best[2]):
                best = (a + 1, b + 1, angle)
    return best
