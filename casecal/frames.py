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


def rpy_from_matrix(R: np.ndarray) -> tuple[float, float, float]:
    """Inverse of `matrix_from_rpy` (ry in [-π/2, π/2]); rad."""
    ry = float(np.arcsin(np.clip(-R[2, 0], -1.0, 1.0)))
    rx = float(np.arctan2(R[2, 1], R[2, 2]))
    rz = float(np.arctan2(R[1, 0], R[0, 0]))
    return rx, ry, rz


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
