"""Small dense linear algebra shared by the solvers, the analysis and the covariance.

Every factorisation here works on column-scaled Jacobians (each column divided by its
norm), so that metres and radians do not decide ranks or cut-offs, and on the small R
factor of a tall Jacobian instead of the Jacobian itself.
"""

from __future__ import annotations

import numpy as np


def nr_threshold(s: np.ndarray, shape: tuple[int, int]) -> float:
    """Numerical Recipes' singular-value cut-off: ``0.5 √(m + n + 1) · s_max · ε``.

    Singular values below it are rounding noise and are set to zero in the pseudo-inverse
    (Press et al., *Numerical Recipes*, 3rd ed., §2.6), as the paper does.
    """
    m, n = shape
    return 0.5 * np.sqrt(m + n + 1.0) * (s[0] if s.size else 0.0) * np.finfo(float).eps


def triangular(J: np.ndarray, r: np.ndarray | None = None):
    """Reduce a tall ``J`` (and ``r``) to the R factor of its QR decomposition.

    ``J = Q R`` keeps every inner product of columns (``JᵀJ = RᵀR``), so the singular values,
    right singular vectors and least-squares solution of ``J`` are those of the small R,
    with ``Qᵀ r`` in place of ``r``. QR of ``[J | r]`` gives both at once, several times
    faster than an SVD of the tall ``J``.

    Returns
    -------
    R : ndarray, shape (min(m, k), k)
    Qtr : ndarray, shape (min(m, k),) or None
    """
    m, k = J.shape
    if r is None:
        return (np.linalg.qr(J, mode="r") if m > k else J), None
    if m <= k:
        return J, r
    Ra = np.linalg.qr(np.column_stack([J, r]), mode="r")
    return Ra[:k, :k], Ra[:k, k]


ZERO_COLUMN = 1e-8
"""A column below this fraction of the largest one is zero: scaling it to unit norm would
turn the rounding it holds (a wrist angle seen through a lever of 1e-17 m) into a full
direction and a step of degrees. The rank tolerance of the analysis, for the same reason."""


def column_scales(J: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Column norms of `J` to scale by, and which columns count as zero (`ZERO_COLUMN`)."""
    norms = np.linalg.norm(J, axis=0)
    zero = norms <= ZERO_COLUMN * max(norms.max(initial=0.0), np.finfo(float).tiny)
    return np.where(zero, 1.0, norms), zero


def svd_solve(J: np.ndarray, r: np.ndarray) -> np.ndarray:
    """``x = D V S⁺ Uᵀ r`` for the column-scaled ``J D``: the paper's SVD least squares.

    Computed on the R factor of ``J D`` (`triangular`): the same singular values and V.
    """
    norms, zero = column_scales(J)
    R, Qtr = triangular(np.where(zero, 0.0, J / norms), r)
    U, s, Vt = np.linalg.svd(R, full_matrices=False)
    keep = s > nr_threshold(s, J.shape)
    z = Vt[keep].T @ ((U[:, keep].T @ Qtr) / s[keep])
    return z / norms


def gauss_newton_step(J: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, float]:
    """The Gauss-Newton step of the scaled problem and the cost decrease it predicts.

    Returns
    -------
    step : ndarray, shape (k,)
        `svd_solve` of ``J`` and ``r``.
    predicted : float
        ``0.5 |r|² - 0.5 |r - J step|²`` of the linear model: what one more step could
        still gain. Zero at a minimum; the convergence and optimality tests use it.
    """
    norms, zero = column_scales(J)
    R, Qtr = triangular(np.where(zero, 0.0, J / norms), r)
    U, s, Vt = np.linalg.svd(R, full_matrices=False)
    keep = s > nr_threshold(s, J.shape)
    proj = U[:, keep].T @ Qtr
    z = Vt[keep].T @ (proj / s[keep])
    return z / norms, 0.5 * float(proj @ proj)
