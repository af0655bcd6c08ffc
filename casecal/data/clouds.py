"""Point clouds compared up to where they stand: similarity and rigid fits (Umeyama)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Similarity:
    """``measured ≈ scale · R · nominal + t``, with spreads and residual in m (RMS)."""

    scale: float
    residual: float
    spread_nominal: float
    spread_measured: float

    @property
    def shape_error(self) -> float:
        """RMS residual relative to the measured cloud's RMS spread (0: a perfect copy)."""
        return self.residual / self.spread_measured if self.spread_measured > 0 else math.inf


def similarity(nominal: np.ndarray, measured: np.ndarray) -> Similarity:
    """Umeyama's least-squares similarity fit of point clouds.

    Parameters
    ----------
    nominal, measured : ndarray, shape (K, 3)
        Corresponding points, m.

    Returns
    -------
    Similarity
        Scale, RMS residual (m) and the RMS distances of each cloud from its centroid (m).
    """
    a = nominal - nominal.mean(axis=0)
    b = measured - measured.mean(axis=0)
    var_a = float(np.mean(np.sum(a * a, axis=1)))
    var_b = float(np.mean(np.sum(b * b, axis=1)))
    if var_a <= 0:
        return Similarity(math.nan, math.sqrt(var_b), 0.0, math.sqrt(var_b))
    R, trace = _rotation(a, b)
    scale = trace / len(a) / var_a
    # the residual itself, not var_b - scale² var_a: that cancels to rounding noise
    residual = b - scale * a @ R.T
    rms = math.sqrt(float(np.mean(np.sum(residual * residual, axis=1))))
    return Similarity(scale, rms, math.sqrt(var_a), math.sqrt(var_b))


def rigid_rms(nominal: np.ndarray, measured: np.ndarray) -> float:
    """RMS residual (m) of the best rotation and translation of `nominal` onto `measured`."""
    a = nominal - nominal.mean(axis=0)
    b = measured - measured.mean(axis=0)
    R, _ = _rotation(a, b)
    residual = b - a @ R.T
    return math.sqrt(float(np.mean(np.sum(residual * residual, axis=1))))


def _rotation(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, float]:
    """The rotation R turning centred `a` best onto centred `b` (Kabsch, no reflection),
    and the sum of the signed singular values of bᵀa (Σ b_k · R a_k)."""
    U, S, Vt = np.linalg.svd(b.T @ a)
    d = np.ones(3)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:
        d[2] = -1.0
    return U @ np.diag(d) @ Vt, float(np.sum(S * d))
