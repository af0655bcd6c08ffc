"""Pixel residuals of a robot seeing a checkerboard, and their exact Jacobian.

For view i and corner c (`casecal.observations.camera`, design note)::

    r = (uv_meas − π(K, T_cam←target(q_i, θ) · c)) / σ_px

with the columns of ∂r/∂(θ, camera pose, target pose, intrinsics) by the chain rule
``−(1/σ) ∂π/∂p · ∂p/∂·``. The robot's columns come from `casecal.Robot.pose_jacobian` in
deviations (``deviations=True``: what `casecal.identify` estimates, `Robot.with_deviations`
applies them), whose rows are δposition and the rotation δφ of the tool frame, both in the
base frame (``δR = [δφ]× R``).

The camera's and the target's poses each get six columns, deviations about the given pose
in its parent frame (the tool's or the base's, `casecal.observations.simulate.CameraSetup`)::

    T(δ) = [exp([δw]×) R | t + δt],   δ = (δt_x, δt_y, δt_z, δw_x, δw_y, δw_z)   (m, rad)

named ``camera_x camera_y camera_z camera_wx camera_wy camera_wz`` and ``target_x …
target_wz``: the w's are a rotation vector's components, not roll-pitch-yaw angles (no
gimbal lock; `apply_pose_deviation` applies them). The intrinsics' nine columns are named
as `casecal.observations.camera.INTRINSIC_NAMES`.

Not yet here (refused, not approximated): trees, missing corners (NaN pixels), per-view
corner orders (a symmetric board's detections must be put in `Checkerboard.corners` order
first).
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import CalibrationError
from ..model.frames import rotation_from_vector
from .camera import INTRINSIC_NAMES, Intrinsics, jacobian_intrinsics, jacobian_point, project
from .simulate import CameraSetup, tool_poses

CAMERA_POSE_NAMES = tuple(f"camera_{a}" for a in ("x", "y", "z", "wx", "wy", "wz"))
TARGET_POSE_NAMES = tuple(f"target_{a}" for a in ("x", "y", "z", "wx", "wy", "wz"))


def apply_pose_deviation(T, delta) -> np.ndarray:
    """``T(δ) = [exp([δw]×) R | t + δt]``: the pose `T` (4, 4) moved by δ (6,) (m, rad)."""
    T = np.asarray(T, dtype=float)
    delta = np.asarray(delta, dtype=float)
    out = T.copy()
    out[:3, :3] = rotation_from_vector(delta[3:]) @ T[:3, :3]
    out[:3, 3] = T[:3, 3] + delta[:3]
    return out


def skew(a: np.ndarray) -> np.ndarray:
    """[a]× for vectors a (..., 3): matrices (..., 3, 3) with [a]× b = a × b."""
    S = np.zeros((*a.shape, 3))
    S[..., 0, 1], S[..., 0, 2], S[..., 1, 2] = -a[..., 2], a[..., 1], -a[..., 0]
    return S - np.swapaxes(S, -1, -2)


def camera_residuals(
    robot,
    q,
    pixels,
    setup: CameraSetup,
    sigma_px: float = 1.0,
    parameters=None,
    poses: bool = True,
    intrinsics: bool = True,
) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Weighted pixel residuals and their exact Jacobian.

    Parameters
    ----------
    robot : casecal.Robot
        A serial robot (coupled, with inputs or sessions too: `q` as for `Robot.fk`).
    q : array-like, shape (N, dof) or (dof,)
        Joint values of the N views, rad (R) or m (P).
    pixels : array-like, shape (N, corners, 2) or (corners, 2)
        Measured (u, v) of every corner of `setup.board`, pixels, in `Checkerboard.corners`
        order; all finite.
    setup : CameraSetup
        The mode, camera and target poses, intrinsics and board at which to linearise.
    sigma_px : float
        Standard deviation of a pixel coordinate's noise, px; the residuals are divided by it.
    parameters : str, list of str or None
        The robot's parameters for columns (`casecal.model.parameters.select`); None: all;
        ``[]``: none.
    poses : bool
        Whether to add the camera's and the target's six columns each.
    intrinsics : bool
        Whether to add the nine intrinsics' columns.

    Returns
    -------
    r : ndarray, shape (2 · N · corners,)
        ``(uv_meas − π(...)) / σ`` ordered view, corner, (u, v): ``r.reshape(N, corners, 2)``.
    J : ndarray, shape (2 · N · corners, k)
        ∂r/∂(columns), per unit of each column (m, rad, px or dimensionless).
    names : list of str
        The k column names: the robot's, then `CAMERA_POSE_NAMES`, `TARGET_POSE_NAMES`,
        then `INTRINSIC_NAMES`, as asked.

    Raises
    ------
    CalibrationError
        For pixels of the wrong shape or not finite, a corner behind the camera, a tree, a
        σ ≤ 0, or a robot parameter named like a camera column.
    """
    sigma = float(sigma_px)
    if not (math.isfinite(sigma) and sigma > 0):
        raise CalibrationError(f"camera_residuals: sigma_px = {sigma_px!r}; give a noise > 0 px")
    T = tool_poses(robot, q)
    n, m = len(T), setup.board.n_corners
    uv = np.asarray(pixels, dtype=float)
    if uv.ndim == 2:
        uv = uv[None]
    if uv.shape != (n, m, 2):
        raise CalibrationError(
            f"camera_residuals: pixels of shape {np.shape(pixels)}; give ({n}, {m}, 2): (u, v) "
            f"of the board's {m} corners in each of the {n} views"
        )
    if not np.all(np.isfinite(uv)):
        raise CalibrationError(
            "camera_residuals: some pixels are not finite; views with missing corners are not "
            "supported yet — leave those views out"
        )
    if parameters is not None and not isinstance(parameters, str) and len(parameters) == 0:
        Jrob, robot_names = np.zeros((n, 6, 0)), []
    else:
        Jrob, robot_names = robot.pose_jacobian(q, parameters, deviations=True)
        Jrob = Jrob.reshape(n, 6, -1)
    extra = [*CAMERA_POSE_NAMES, *TARGET_POSE_NAMES, *INTRINSIC_NAMES]
    clash = sorted(set(robot.parameter_names) & set(extra))
    if clash:
        raise CalibrationError(
            f"camera_residuals: robot {robot.name!r} has parameters named like camera columns "
            f"({', '.join(clash)}); rename them"
        )

    R, t = T[:, :3, :3], T[:, :3, 3]
    Rc, tc = setup.camera[:3, :3], setup.camera[:3, 3]
    Rg, tg = setup.target[:3, :3], setup.target[:3, 3]
    c = setup.board.corners()
    cg = c @ Rg.T  # corners turned into the target's parent frame, (m, 3)
    Jpos, Jrot = Jrob[:, :3], Jrob[:, 3:]
    if setup.mode == "eye_in_hand":
        # p = Rcᵀ (Rᵀ (Rg c + tg − t) − tc); Rc, tc: the camera in the tool frame
        w = (cg + tg)[None] - t[:, None]  # (n, m, 3), base frame
        v = np.einsum("nji,nmj->nmi", R, w) - tc  # tool frame, from the camera's origin
        p = v @ Rc
        to_cam = np.einsum("ji,nkj->nik", Rc, R)  # Rcᵀ Rᵀ, (n, 3, 3)
        # δp_tool = Rᵀ ([w]× δφ − δt)
        dp_robot = np.einsum("nij,nmjk->nmik", to_cam, skew(w) @ Jrot[:, None] - Jpos[:, None])
        dp_camera = np.concatenate([np.broadcast_to(-Rc.T, (n, m, 3, 3)), Rc.T @ skew(v)], axis=-1)
        dp_target = np.concatenate(
            [np.broadcast_to(to_cam[:, None], (n, m, 3, 3)), -to_cam[:, None] @ skew(cg)[None]],
            axis=-1,
        )
    else:
        # p = Rcᵀ (R (Rg c + tg) + t − tc); Rc, tc: the camera in the base frame
        a = np.einsum("nij,mj->nmi", R, cg + tg)  # (n, m, 3), base frame
        u = a + (t - tc)[:, None]
        p = u @ Rc
        # δp_base = δt − [a]× δφ
        dp_robot = Rc.T @ (Jpos[:, None] - skew(a) @ Jrot[:, None])
        dp_camera = np.concatenate([np.broadcast_to(-Rc.T, (n, m, 3, 3)), Rc.T @ skew(u)], axis=-1)
        RcR = Rc.T @ R  # (n, 3, 3)
        dp_target = np.concatenate(
            [np.broadcast_to(RcR[:, None], (n, m, 3, 3)), -RcR[:, None] @ skew(cg)[None]],
            axis=-1,
        )
    flat = p.reshape(-1, 3)
    predicted = project(setup.intrinsics, flat).reshape(n, m, 2)
    Jp = jacobian_point(setup.intrinsics, flat).reshape(n, m, 2, 3)
    blocks = [Jp @ dp_robot]
    names = list(robot_names)
    if poses:
        blocks += [Jp @ dp_camera, Jp @ dp_target]
        names += [*CAMERA_POSE_NAMES, *TARGET_POSE_NAMES]
    if intrinsics:
        blocks.append(jacobian_intrinsics(setup.intrinsics, flat).reshape(n, m, 2, 9))
        names += list(INTRINSIC_NAMES)
    J = np.concatenate(blocks, axis=-1).reshape(2 * n * m, -1) * (-1.0 / sigma)
    r = ((uv - predicted) / sigma).ravel()
    return r, J, names


def moved_setup(setup: CameraSetup, deltas) -> CameraSetup:
    """`setup` moved by deviations named as `camera_residuals`' camera, target and
    intrinsics columns (a mapping name → value, m, rad, px or dimensionless)."""
    known = {*CAMERA_POSE_NAMES, *TARGET_POSE_NAMES, *INTRINSIC_NAMES}
    unknown = sorted(set(deltas) - known)
    if unknown:
        raise CalibrationError(
            f"moved_setup: unknown names {', '.join(unknown)}; give camera_*, target_* or "
            f"{', '.join(INTRINSIC_NAMES)}"
        )
    cam = [float(deltas.get(k, 0.0)) for k in CAMERA_POSE_NAMES]
    tgt = [float(deltas.get(k, 0.0)) for k in TARGET_POSE_NAMES]
    intr = setup.intrinsics.vector() + [float(deltas.get(k, 0.0)) for k in INTRINSIC_NAMES]
    return CameraSetup(
        setup.mode,
        apply_pose_deviation(setup.camera, cam),
        apply_pose_deviation(setup.target, tgt),
        Intrinsics.from_vector(intr),
        setup.board,
        setup.image_size,
    )
