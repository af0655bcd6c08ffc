"""Simulated camera data: pixels of a checkerboard's corners seen eye-in-hand or eye-to-hand.

A `CameraSetup` says where the camera and the board are:

- ``"eye_in_hand"``: the camera on the flange, its pose ``camera`` = T_tool←cam (the hand-eye
  transform, in the tool frame); the board fixed, its pose ``target`` = T_base←target;
- ``"eye_to_hand"``: the camera fixed, its pose ``camera`` = T_base←cam; the board on the
  flange, its pose ``target`` = T_tool←target.

"Base" is the frame `casecal.Robot.fk` gives the tool's poses in: the world outside the
robot's own base frame (the same as the robot's base only where `Robot.base` is identity).
The camera frame is OpenCV's (z along the optical axis, x right, y down in the image);
the board frame is `casecal.observations.target`'s. All pure functions; randomness only
through an explicit seed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import CalibrationError
from .camera import Intrinsics, in_front, project, radially_monotonic
from .target import Checkerboard

MODES = ("eye_in_hand", "eye_to_hand")


def _rigid(T, what: str) -> np.ndarray:
    T = np.asarray(T, dtype=float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise CalibrationError(f"{what}: give a finite 4 × 4 homogeneous transform (m)")
    R = T[:3, :3]
    if (
        not np.allclose(R @ R.T, np.eye(3), atol=1e-9)
        or not np.isclose(np.linalg.det(R), 1.0, atol=1e-9)
        or not np.array_equal(T[3], [0.0, 0.0, 0.0, 1.0])
    ):
        raise CalibrationError(
            f"{what}: not a rigid transform (its rotation is not orthonormal with det +1 to "
            "1e-9, or its last row is not 0 0 0 1)"
        )
    T = T.copy()
    T.setflags(write=False)
    return T


def inverse(T: np.ndarray) -> np.ndarray:
    """Inverse of rigid transforms, shape (..., 4, 4)."""
    T = np.asarray(T, dtype=float)
    out = np.zeros_like(T)
    Rt = np.swapaxes(T[..., :3, :3], -1, -2)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, T[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


@dataclass(frozen=True, eq=False)
class CameraSetup:
    """Where the camera and the board are, and what the camera is.

    Attributes
    ----------
    mode : {"eye_in_hand", "eye_to_hand"}
    camera : ndarray, shape (4, 4)
        The camera's pose: T_tool←cam (eye-in-hand) or T_base←cam (eye-to-hand), m.
    target : ndarray, shape (4, 4)
        The board's pose: T_base←target (eye-in-hand) or T_tool←target (eye-to-hand), m.
    intrinsics : Intrinsics
    board : Checkerboard
    image_size : (int, int)
        (width, height), pixels.
    """

    mode: str
    camera: np.ndarray
    target: np.ndarray
    intrinsics: Intrinsics
    board: Checkerboard = field(default_factory=Checkerboard)
    image_size: tuple[int, int] = (1280, 1024)

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise CalibrationError(
                f"CameraSetup: mode {self.mode!r}; give one of {', '.join(MODES)}"
            )
        object.__setattr__(self, "camera", _rigid(self.camera, "CameraSetup camera pose"))
        object.__setattr__(self, "target", _rigid(self.target, "CameraSetup target pose"))
        if not isinstance(self.intrinsics, Intrinsics):
            raise CalibrationError("CameraSetup: intrinsics must be an Intrinsics")
        if not isinstance(self.board, Checkerboard):
            raise CalibrationError("CameraSetup: board must be a Checkerboard")
        size = tuple(self.image_size)
        if len(size) != 2 or not all(
            isinstance(v, int | np.integer) and not isinstance(v, bool) and v > 0 for v in size
        ):
            raise CalibrationError(
                f"CameraSetup: image_size {self.image_size!r}; give (width, height) in "
                "pixels, positive integers"
            )
        object.__setattr__(self, "image_size", (int(size[0]), int(size[1])))


def tool_poses(robot, q) -> np.ndarray:
    """`robot.fk(q)` as (N, 4, 4); a tree (several tips) is refused: which tip holds the
    camera or board is not defined yet."""
    if robot.is_tree:
        raise CalibrationError(
            f"robot {robot.name!r} is a tree; camera observations support serial robots only "
            "(one tool frame holding the camera or the board)"
        )
    T = robot.fk(q)
    return T[None] if T.ndim == 2 else T


def points_in_camera(robot, q, setup: CameraSetup) -> np.ndarray:
    """The board's corners in the camera frame for each pose, m, shape (N, corners, 3).

    Eye-in-hand: ``T_cam←tool · T_tool←base(q) · T_base←target · c``; eye-to-hand:
    ``T_cam←base · T_base←tool(q) · T_tool←target · c``.
    """
    T = tool_poses(robot, q)
    if setup.mode == "eye_in_hand":
        chain = inverse(setup.camera) @ inverse(T) @ setup.target
    else:
        chain = inverse(setup.camera) @ T @ setup.target
    c = setup.board.corners()
    return np.einsum("nij,mj->nmi", chain[:, :3, :3], c) + chain[:, None, :3, 3]


def simulate_pixels(robot, q, setup: CameraSetup, sigma_px: float = 0.0, seed=None) -> np.ndarray:
    """Pixels of every corner in every pose, with Gaussian noise.

    Parameters
    ----------
    robot : casecal.Robot
        A serial robot (the truth of the simulation).
    q : array-like, shape (N, dof) or (dof,)
        Joint values, rad (R) or m (P).
    setup : CameraSetup
    sigma_px : float
        Standard deviation of the noise on u and on v (independent), pixels; ≥ 0.
    seed : int, numpy Generator or None
        For the noise (`numpy.random.default_rng`); needed when sigma_px > 0.

    Returns
    -------
    ndarray, shape (N, corners, 2)
        (u, v) pixels, corners in `Checkerboard.corners` order.

    Raises
    ------
    CalibrationError
        When a corner is behind the camera or falls outside the image (a detector would
        not see it; pick views with `select_views`).
    """
    sigma = float(sigma_px)
    if not (math.isfinite(sigma) and sigma >= 0):
        raise CalibrationError(f"simulate_pixels: sigma_px = {sigma_px!r}; give a noise ≥ 0 px")
    if sigma > 0 and seed is None:
        raise CalibrationError(
            "simulate_pixels: noisy pixels need an explicit seed (seed=...), so runs repeat"
        )
    p = points_in_camera(robot, q, setup)
    n, m, _ = p.shape
    front = in_front(p).all(axis=1)
    if not front.all():
        raise CalibrationError(
            f"simulate_pixels: in {np.count_nonzero(~front)} of {n} poses (first: "
            f"{np.flatnonzero(~front)[:5].tolist()}) corners are behind the camera; "
            "pick poses with select_views"
        )
    uv = project(setup.intrinsics, p.reshape(-1, 3)).reshape(n, m, 2)
    inside = _inside(uv, setup.image_size, 0.0).all(axis=1)
    if not inside.all():
        raise CalibrationError(
            f"simulate_pixels: in {np.count_nonzero(~inside)} of {n} poses (first: "
            f"{np.flatnonzero(~inside)[:5].tolist()}) corners fall outside the "
            f"{setup.image_size[0]} × {setup.image_size[1]} image; pick poses with select_views"
        )
    if sigma > 0:
        uv = uv + np.random.default_rng(seed).normal(0.0, sigma, uv.shape)
    return uv


def _inside(uv: np.ndarray, size: tuple[int, int], margin: float) -> np.ndarray:
    # OpenCV's pixel centres are at integers: the image spans [-0.5, W - 0.5]
    w, h = size
    u, v = uv[..., 0], uv[..., 1]
    lo = margin - 0.5
    return (u >= lo) & (u <= w - 0.5 - margin) & (v >= lo) & (v <= h - 0.5 - margin)


def board_tilt(robot, q, setup: CameraSetup) -> np.ndarray:
    """Angle between the board's normal and the line of sight to its centre, rad, (N,).

    0 for a board square to the camera; above π/2 when the camera sees the board's back
    (its +z side; the printed face is the −z side, `casecal.observations.target`).
    """
    T = tool_poses(robot, q)
    if setup.mode == "eye_in_hand":
        target = inverse(setup.camera) @ inverse(T) @ setup.target
    else:
        target = inverse(setup.camera) @ T @ setup.target
    centre = target[:, :3, :3] @ setup.board.centre + target[:, :3, 3]  # camera frame
    normal = target[:, :3, 2]
    cos = np.einsum("ni,ni->n", normal, centre) / np.linalg.norm(centre, axis=1)
    return np.arccos(np.clip(cos, -1.0, 1.0))


def visible(
    robot, q, setup: CameraSetup, max_tilt: float = math.radians(60), margin_px: float = 10.0
) -> np.ndarray:
    """Which poses see the whole board usably, (N,) bool.

    Every corner in front of the camera and at least `margin_px` inside the image, inside
    the radius where the distortion model is one-to-one (`radially_monotonic`), and the
    board's printed face turned to the camera by at most `max_tilt` (rad).
    """
    p = points_in_camera(robot, q, setup)
    m = p.shape[1]
    ok = in_front(p).all(axis=1)
    ok &= board_tilt(robot, q, setup) <= max_tilt
    if ok.any():
        good = p[ok].reshape(-1, 3)
        uv = project(setup.intrinsics, good).reshape(-1, m, 2)
        mono = radially_monotonic(setup.intrinsics, good).reshape(-1, m)
        ok[np.flatnonzero(ok)] = (_inside(uv, setup.image_size, margin_px) & mono).all(axis=1)
    return ok


def select_views(
    robot,
    n: int,
    setup: CameraSetup,
    seed,
    q_centre=None,
    spread: float | None = None,
    max_tilt: float = math.radians(60),
    margin_px: float = 10.0,
    max_draws: int = 200_000,
) -> np.ndarray:
    """`n` random joint poses that each see the whole board (`visible`).

    Parameters
    ----------
    robot : casecal.Robot
        A serial robot without inputs or sessions.
    n : int
        Number of poses.
    setup : CameraSetup
    seed : int or numpy Generator
        Explicit, so runs repeat.
    q_centre : array-like, shape (dof,), or None
        None: draw uniformly within the joint limits. Else draw ``q_centre + spread · N(0, 1)``
        per joint, clipped to the limits: a camera sees a board only from a small part of
        the joint space, where uniform draws rarely land.
    spread : float or None
        Standard deviation of the draws about `q_centre`, rad (m for a prismatic joint);
        needed with `q_centre`.
    max_tilt, margin_px : float
        As for `visible`: rad, pixels.
    max_draws : int
        Give up after this many draws.

    Returns
    -------
    ndarray, shape (n, dof)

    Raises
    ------
    CalibrationError
        When fewer than `n` of `max_draws` draws see the board.
    """
    if robot.inputs or robot.sessions:
        raise CalibrationError(
            "select_views: the robot has inputs or sessions; draw its views for a robot "
            "without them"
        )
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 1:
        raise CalibrationError(f"select_views: n = {n!r}; give a number of poses ≥ 1")
    limits = robot.limits
    rng = np.random.default_rng(seed)
    if q_centre is not None:
        q_centre = np.asarray(q_centre, dtype=float)
        if q_centre.shape != (robot.dof,):
            raise CalibrationError(
                f"select_views: q_centre of shape {q_centre.shape}; give ({robot.dof},) values"
            )
        if spread is None or not (math.isfinite(spread) and spread > 0):
            raise CalibrationError(
                f"select_views: spread = {spread!r}; give the draws' standard deviation, > 0"
            )
    chosen: list[np.ndarray] = []
    found, draws = 0, 0
    while found < n and draws < max_draws:
        batch = min(1024, max_draws - draws)
        if q_centre is None:
            q = rng.uniform(limits[:, 0], limits[:, 1], (batch, robot.dof))
        else:
            q = np.clip(q_centre + spread * rng.standard_normal((batch, robot.dof)), *limits.T)
        draws += batch
        good = q[visible(robot, q, setup, max_tilt, margin_px)]
        chosen.append(good)
        found += len(good)
    if found < n:
        raise CalibrationError(
            f"select_views: only {found} of {draws} random poses see the whole board, "
            f"{n} wanted; draw about a pose that sees it (q_centre, spread), loosen max_tilt "
            "or margin_px, or move the board or camera"
        )
    return np.concatenate(chosen)[:n]


def look_at(eye, centre, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """A camera pose at `eye` looking at `centre` (OpenCV frame: z forward, y down), (4, 4).

    Parameters
    ----------
    eye, centre : array-like, shape (3,)
        Positions in the parent frame, m.
    up : array-like, shape (3,)
        The parent's direction that should appear upwards in the image (−y of the camera).
    """
    eye, centre, up = (np.asarray(v, dtype=float) for v in (eye, centre, up))
    z = centre - eye
    if np.linalg.norm(z) == 0:
        raise CalibrationError("look_at: eye and centre coincide; give distinct points")
    z = z / np.linalg.norm(z)
    x = np.cross(z, up)
    if np.linalg.norm(x) < 1e-9:
        raise CalibrationError("look_at: the line of sight is parallel to up; give another up")
    x = x / np.linalg.norm(x)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, :3] = np.stack([x, y, z], axis=1)
    T[:3, 3] = eye
    return T
