"""Compensated joint targets: how to apply a calibration to a controller that takes no new
parameters.

The controller believes the nominal robot: sent joint values q_t, it expects the tool at
``T_nominal(q_t)``. The real robot (the calibrated model) puts it at ``T_calibrated(q_t)``
instead. Sending the joint values q with ``T_calibrated(q) = T_nominal(q_t)`` puts the
tool where the controller meant. Newton iterations on the exact joint Jacobian, all poses
at once; the full tool pose for arms of six or more joints, its position for fewer.

Both robots are taken in their own base frames: a calibrated base frame holds where the
instrument stood, which the controller never knew.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..errors import CalibrationError
from . import kinematics
from .frames import rotation_vector
from .robot import Frame, Robot, check_joint_values

TOLERANCE = 1e-12  # m and rad: a Newton step this small has converged
SINGULAR = 1e-9  # smallest over largest singular value of the joint Jacobian
REACHED = 1e-9  # m and rad: a row whose tool ends farther off than this has failed


@dataclass(frozen=True)
class Compensation:
    """Corrected joint values and, per row, whether they can be used.

    Attributes
    ----------
    q : ndarray, shape (N, dof)
        Joint values to send, rad (R) or m (P); the target itself on rows that failed.
    ok : ndarray of bool, shape (N,)
        Converged, not singular and within the joint limits.
    position_error, orientation_error : ndarray, shape (N,)
        Where the calibrated robot's tool ends at the returned values, against the target,
        m and rad (0 for an arm of fewer than six joints, where only the position is
        matched); on a failed row, the error the uncorrected target leaves.
    reason : tuple of str
        Per row: "" when `ok`, else "singular", "no convergence", "out of reach (…)" or
        "outside the limits of joint k".
    """

    q: np.ndarray
    ok: np.ndarray
    position_error: np.ndarray
    orientation_error: np.ndarray
    reason: tuple[str, ...]


def _without_base(robot: Robot) -> Robot:
    return dataclasses.replace(robot, base=Frame(), auto_beta=False)


def _errors(calibrated: Robot, q: np.ndarray, target: np.ndarray) -> np.ndarray:
    T = calibrated.fk(q)
    rot = rotation_vector(target[:, :3, :3] @ np.transpose(T[:, :3, :3], (0, 2, 1)))
    return np.concatenate([target[:, :3, 3] - T[:, :3, 3], rot], axis=1)


def compensate(
    calibrated: Robot, q_targets, nominal: Robot | None = None, max_iterations: int = 30
) -> Compensation:
    """Joint values that bring `calibrated` to where `nominal` would be at `q_targets`.

    Parameters
    ----------
    calibrated : Robot
        The real robot, as identified.
    q_targets : array-like, shape (N, dof) or (dof,)
        The joint values the program sends today, rad (R) or m (P).
    nominal : Robot, optional
        The robot the controller believes; default the one `calibrated` was calibrated
        from (its ``calibrated_from``).
    max_iterations : int

    Returns
    -------
    Compensation
    """
    if nominal is None:
        if not calibrated.calibrated_from:
            raise CalibrationError(
                "compensate needs the nominal robot: pass nominal=, or use a robot file "
                "written by identify (it records calibrated_from)"
            )
        from .catalog import nominal_of

        nominal = nominal_of(calibrated)
    if nominal.dof != calibrated.dof:
        raise CalibrationError(
            f"the nominal robot has {nominal.dof} joints, the calibrated one {calibrated.dof}"
        )
    q_t, _ = check_joint_values(q_targets, calibrated.dof)
    real, believed = _without_base(calibrated), _without_base(nominal)
    target = believed.fk(q_t)
    rows = slice(None) if real.dof >= 6 else slice(0, 3)
    chain = kinematics.chain(real.structure)
    q = q_t.copy()
    converged = np.zeros(len(q), dtype=bool)
    singular = np.zeros(len(q), dtype=bool)
    for _ in range(max_iterations):
        e = _errors(real, q, target)[:, rows]
        J = chain.evaluate("joint_jacobian", q, real.vector())[:, rows, :]
        s = np.linalg.svd(J, compute_uv=False)
        singular = s[:, -1] <= SINGULAR * s[:, 0]
        step = np.einsum("nij,nj->ni", np.linalg.pinv(J), e)
        q = q + np.where(singular[:, None], 0.0, step)
        # a step this small, or an error this small (it cannot shrink below rounding)
        converged = (np.max(np.abs(step), axis=1) < TOLERANCE) | (
            np.max(np.abs(e), axis=1) < TOLERANCE
        )
        if np.all(converged | singular):
            break
    e = _errors(real, q, target)
    miss = np.max(np.abs(e[:, rows]), axis=1)
    # a joint without limits (continuous) turns freely: its default range is for sampling
    lo = np.array([-np.inf if j.limits is None else j.limits[0] for j in real.joints])
    hi = np.array([np.inf if j.limits is None else j.limits[1] for j in real.joints])
    outside = (q[:, : real.dof] < lo - 1e-12) | (q[:, : real.dof] > hi + 1e-12)
    ok = converged & (miss <= REACHED) & ~outside.any(axis=1)
    reason = [""] * len(q)
    for k in np.flatnonzero(~ok):  # words only for the rows that need them
        if not converged[k]:
            reason[k] = "singular" if singular[k] else "no convergence"
        elif miss[k] > REACHED:
            reason[k] = f"out of reach ({miss[k] * 1e3:.3g} mm or mrad off)"
        else:
            reason[k] = f"outside the limits of joint {int(np.argmax(outside[k])) + 1}"
    q = np.where(ok[:, None], q, q_t)
    e = _errors(real, q, target)  # where the returned values put the tool
    return Compensation(
        q=q,
        ok=ok,
        position_error=np.linalg.norm(e[:, :3], axis=1),
        orientation_error=np.linalg.norm(e[:, 3:], axis=1) if real.dof >= 6 else np.zeros(len(q)),
        reason=tuple(reason),
    )
