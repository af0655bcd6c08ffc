"""Covariance and standard errors of estimated deviations."""

from __future__ import annotations

import numpy as np

from .linalg import Reduction, nr_threshold


def covariance(J, r, known: bool, prior_w=None) -> np.ndarray:
    """``(JᵀJ + W_p²)⁻¹`` of the weighted Jacobian `J` and prior weights ``W_p = 1/σ_p``.

    Parameters
    ----------
    J : ndarray, shape (rows, k), or Reduction
        Jacobian of the weighted residuals (rows divided by their σ when it is known), or
        the `Reduction` of it and the residuals (then `r` is None).
    r : ndarray, shape (rows,), or None
        Weighted residuals at the solution.
    known : bool
        Whether the weights are 1/σ. If not, the covariance is scaled by the residual
        variance ``RSS / (rows - k)`` (NaN without residual degrees of freedom).
    prior_w : ndarray, shape (k,), optional

    Returns
    -------
    ndarray, shape (k, k)
        In the units of the parameters (m², m·rad, rad²).
    """
    red = J if isinstance(J, Reduction) else Reduction.of(J, r)
    k = red.k
    if k == 0:
        return np.zeros((0, 0))
    data = red
    if prior_w is not None and np.any(prior_w > 0):
        red = red.fold(np.diag(prior_w), np.zeros(k))
    norms = red.norms
    norms[norms == 0] = 1.0
    _, s, Vt = np.linalg.svd(red.R / norms, full_matrices=False)
    keep = s > nr_threshold(s, (red.rows, k))
    inv = (Vt[keep].T / s[keep] ** 2) @ Vt[keep]
    cov = inv / np.outer(norms, norms)
    if not known:
        dof = data.rows - k
        cov = cov * (data.rr / dof if dof > 0 else np.nan)
    return cov


def uncertainty(J, r, known: bool, names, estimated, prior_w=None) -> tuple[np.ndarray, dict]:
    """Covariance of the estimated deviations and standard errors of all asked-for names
    (NaN for those held), from the weighted Jacobian `J` of `estimated` and residuals `r`
    at the solution, or their `Reduction` (see `covariance`)."""
    cov = covariance(J, r, known, prior_w)
    se = dict.fromkeys(names, float("nan"))
    se.update(zip(estimated, np.sqrt(np.diag(cov)).tolist(), strict=True))
    return cov, se
