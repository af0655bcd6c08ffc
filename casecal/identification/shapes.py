"""How far apart two robots' shapes are, and how far the covariance says a fit's may be:
what distances can tell, so rigid motions of the whole point cloud are left out."""

from __future__ import annotations

import numpy as np

from ..model.robot import Robot


def aligned_difference(a: Robot, b: Robot, q) -> tuple[float, float]:
    """RMS and largest distance (m) between the tool points of `a` and `b` at `q` after
    the best proper rigid motion (a rotation, never a reflection)."""
    pa, pb = a.position(q), b.position(q)
    pa, pb = pa - pa.mean(axis=0), pb - pb.mean(axis=0)
    U, _, Vt = np.linalg.svd(pa.T @ pb)
    R = U @ np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))]) @ Vt
    e = np.linalg.norm(pa @ R - pb, axis=1)
    return float(np.sqrt(np.mean(e**2))), float(e.max())


def shape_prediction(robot: Robot, q, estimated, cov) -> float:
    """RMS error (m) of the tool points at `q` that the covariance predicts, rigid motions
    of the whole cloud left out (distances cannot see them, nor need to).

    Parameters
    ----------
    robot : Robot
    q : ndarray, shape (N, dof)
    estimated : sequence of str
        The k estimated parameters.
    cov : ndarray, shape (k, k)
        Their covariance.
    """
    if not estimated:
        return 0.0
    if not np.all(np.isfinite(cov)):
        return float("inf")
    J = robot.position_jacobian(q, list(estimated))[0].reshape(-1, len(estimated))
    p = robot.position(q)
    p = p - p.mean(axis=0)
    # small rigid motions of the cloud: a translation t and a rotation ω, δp = t + ω × p
    rigid = np.zeros((len(p), 3, 6))
    rigid[:, :, :3] = np.eye(3)
    rigid[:, 0, 4], rigid[:, 0, 5] = p[:, 2], -p[:, 1]
    rigid[:, 1, 3], rigid[:, 1, 5] = -p[:, 2], p[:, 0]
    rigid[:, 2, 3], rigid[:, 2, 4] = p[:, 1], -p[:, 0]
    basis = np.linalg.qr(rigid.reshape(-1, 6))[0]
    J = J - basis @ (basis.T @ J)
    return float(np.sqrt(max(np.einsum("ik,kl,il->", J, cov, J) / len(q), 0.0)))
