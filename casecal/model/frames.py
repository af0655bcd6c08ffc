"""Rigid frames: roll-pitch-yaw conversions and the closed-form rigid fit of point sets.

Real measurements come in the instrument's frame (a laser tracker three metres away, turned
by any angle). Linearising at an identity base frame would then start far outside the
region where Gauss-Newton converges; a rigid fit of the nominal positions to the measured
ones (Kabsch / Horn, via one 3 × 3 SVD) gives a starting base frame that is already close.
"""

from __future__ import annotations

import numpy as np


def matrix_from_rpy(rpy) -> np.ndarray:
    """``Rz(rz) Ry(ry) Rx(rx)`` for ``rpy = (rx, ry, rz)`` in rad; shape (3, 3)."""
    rx, ry, rz = rpy
    cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
    return np.array(
        [
            [cz * cy, cz * sy * sx - sz * cx, cz * sy * cx + sz * sx],
            [sz * cy, sz * sy * sx + cz * cx, sz * sy * cx - cz * sx],
            [-sy, cy * sx, cy * cx],
        ]
    )


NEAR_LOCK = 0.1
"""``|cos ry|`` below which `rpy_from_matrix` takes the roll from what the yaw and pitch
leave, rather than from the last row alone."""

AT_LOCK = 1e-14
"""``|cos ry|`` below which the matrix fixes only yaw ∓ roll, to rounding: `rpy_from_matrix`
then keeps the yaw of its `hint`."""


def rpy_from_matrix(R: np.ndarray, hint=None) -> tuple[float, float, float]:
    """Inverse of `matrix_from_rpy` (ry in [-π/2, π/2]); rad.

    Near ry = ±π/2 (gimbal lock) the roll and the yaw are each ill-determined, though the
    matrix is not: taken each from its own entries, their errors (ε / |cos ry|) would not
    cancel, and the rebuilt matrix would be off by as much. There the roll is taken from
    ``Ry(ry)ᵀ Rz(rz)ᵀ R``, so that whatever the yaw's error the three rebuild `R` to
    rounding; at the lock itself (``|cos ry|`` < `AT_LOCK`) the yaw is the `hint`'s
    (rx, ry, rz), when given, so that a frame there keeps the split its file gave.
    """
    R = np.asarray(R, dtype=float)
    # atan2 rather than arcsin(-R[2, 0]): arcsin loses half the digits near ±π/2
    cy = float(np.hypot(R[0, 0], R[1, 0]))
    ry = float(np.arctan2(-R[2, 0], cy))
    rz = float(np.arctan2(R[1, 0], R[0, 0]))
    if cy >= NEAR_LOCK:
        return float(np.arctan2(R[2, 1], R[2, 2])), ry, rz
    if cy < AT_LOCK and hint is not None:
        rz = float(hint[2])
    M = matrix_from_rpy((0.0, ry, rz)).T @ R  # Rx(rx), to rounding
    return float(np.arctan2(M[2, 1], M[1, 1])), ry, rz


def rigid_fit(P: np.ndarray, Y: np.ndarray, weights: np.ndarray | None = None):
    """The rotation R and translation t minimising ``Σ w_i |Y_i - (R P_i + t)|²``.

    Parameters
    ----------
    P, Y : ndarray, shape (N, 3)
        Model points and measured points, m.
    weights : ndarray, shape (N,), optional

    Returns
    -------
    R : ndarray, shape (3, 3)
        A proper rotation (det +1).
    t : ndarray, shape (3,)
    """
    w = np.ones(len(P)) if weights is None else np.asarray(weights, dtype=float)
    w = w / w.sum()
    pc, yc = w @ P, w @ Y
    H = ((P - pc) * w[:, None]).T @ (Y - yc)
    U, _, Vt = np.linalg.svd(H)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    return R, yc - R @ pc


def matrix_from_quaternion(quat: np.ndarray) -> np.ndarray:
    """Rotation matrices (N, 3, 3) from unit quaternions (N, 4) ordered (w, x, y, z)."""
    w, x, y, z = np.moveaxis(np.asarray(quat, dtype=float), -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def quaternion_from_matrix(R: np.ndarray) -> np.ndarray:
    """Unit quaternions (N, 4), (w, x, y, z) with w >= 0, from rotation matrices (N, 3, 3)."""
    R = np.asarray(R, dtype=float)
    tr = np.trace(R, axis1=-2, axis2=-1)
    # the largest of 1 + tr, 1 + 2 R_ii - tr keeps the square root well away from zero
    cand = np.stack(
        [1 + tr, 1 + 2 * R[..., 0, 0] - tr, 1 + 2 * R[..., 1, 1] - tr, 1 + 2 * R[..., 2, 2] - tr],
        -1,
    )
    k = np.argmax(cand, axis=-1)
    s = np.sqrt(np.take_along_axis(cand, k[..., None], -1)[..., 0]) * 2
    r = lambda i, j: R[..., i, j]  # noqa: E731
    quats = [
        np.stack(
            [s / 4, (r(2, 1) - r(1, 2)) / s, (r(0, 2) - r(2, 0)) / s, (r(1, 0) - r(0, 1)) / s], -1
        ),
        np.stack(
            [(r(2, 1) - r(1, 2)) / s, s / 4, (r(0, 1) + r(1, 0)) / s, (r(0, 2) + r(2, 0)) / s], -1
        ),
        np.stack(
            [(r(0, 2) - r(2, 0)) / s, (r(0, 1) + r(1, 0)) / s, s / 4, (r(1, 2) + r(2, 1)) / s], -1
        ),
        np.stack(
            [(r(1, 0) - r(0, 1)) / s, (r(0, 2) + r(2, 0)) / s, (r(1, 2) + r(2, 1)) / s, s / 4], -1
        ),
    ]
    q = np.choose(k[..., None], quats)
    return q * np.where(q[..., :1] < 0, -1.0, 1.0)


def rotation_vector(R: np.ndarray) -> np.ndarray:
    """``vee(log(R))`` for rotations R (..., 3, 3): axis times angle, rad, shape (..., 3).

    Through the unit quaternion (w ≥ 0): angle = 2 atan2(|v|, w), exact up to π, where the
    trace formula loses the axis.
    """
    from ..model.frames import quaternion_from_matrix

    R = np.asarray(R, dtype=float)
    quat = quaternion_from_matrix(R.reshape(-1, 3, 3))
    w, v = quat[:, 0], quat[:, 1:]
    s = np.linalg.norm(v, axis=1)
    angle = 2.0 * np.arctan2(s, w)
    factor = np.where(s > 1e-12, angle / np.where(s > 1e-12, s, 1.0), 2.0 / np.maximum(w, 1e-300))
    return (v * factor[:, None]).reshape(R.shape[:-1])


def rotation_from_vector(w: np.ndarray) -> np.ndarray:
    """``exp([w]×)`` (Rodrigues) for rotation vectors w (..., 3), rad."""
    w = np.asarray(w, dtype=float)
    angle = np.linalg.norm(w, axis=-1)[..., None, None]
    K = np.zeros((*w.shape[:-1], 3, 3))
    K[..., 0, 1], K[..., 0, 2], K[..., 1, 2] = -w[..., 2], w[..., 1], -w[..., 0]
    K = K - np.swapaxes(K, -1, -2)
    safe = np.where(angle > 1e-12, angle, 1.0)
    A = np.where(angle > 1e-12, np.sin(angle) / safe, 1.0)
    B = np.where(angle > 1e-12, (1 - np.cos(angle)) / safe**2, 0.5)
    return np.eye(3) + A * K + B * (K @ K)
