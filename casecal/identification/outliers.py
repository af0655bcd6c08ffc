"""Poses whose residuals stand out from the others: listed, and left out of robust fits.

A pose stands out when one of its points lies farther from the model than Gaussian noise
would put any of the measured points, save in `FALSE_ALARM` of data sets: the limit on
the squared σ-weighted residual norm is the χ²(3) quantile of a Šidák-corrected tail, so
it grows with the number of points and clean data stay clean whatever their number (a
fixed number of robust SDs flagged 49 of two million clean poses). The noise is the
stated σ, or scaled from the median residual (robust to gross rows) when σ is not stated
or the residuals are larger than it says.

Least squares spreads a gross error over the poses near it in the fit, and could name
an innocent pose with the guilty one. Poses are therefore judged against the fit
without the ones that stand out: those are left out, the others refitted (the linear
model at the fit, updated by the left-out rows only, with Gauss-Newton steps where it is
not accurate enough), the left-out ones judged by their prediction error, and this is
repeated until the list no longer changes.
"""

from __future__ import annotations

import numpy as np

from .problem import Problem
from .solvers import SOLVERS

FALSE_ALARM = 0.01
"""Chance that clean Gaussian data have any pose listed, whatever their number."""

OUTLIER_MINIMUM = 1e-9
"""Residual norm, m, a pose must also exceed without a stated σ: below it, residuals are
rounding."""

CHI2_3_MEDIAN = 2.365973884375338
"""Median of χ²(3): of a point's squared residual norm over σ², for Gaussian noise."""

REFITS = 10
"""Refits without the listed poses before the list is taken as it stands."""

SETTLE_ITERATIONS = 50
"""Levenberg-Marquardt iterations a refit may take where its linear model is not enough."""


def outlier_poses(
    problem: Problem, w: np.ndarray, known: bool, refit: bool = False
) -> tuple[int, ...]:
    """Poses whose largest point residual stands out (module doc).

    Parameters
    ----------
    problem : Problem
        At the fitted robot; its ``names`` are the estimated parameters (their number
        is the degrees of freedom the fit took, and what a refit moves).
    w : ndarray, shape (N, 3)
        Position weights 1/σ (ones without a stated σ).
    known : bool
        Whether σ was stated.
    refit : bool
        Judge the poses against the fit without the listed ones (module doc): for a
        least-squares fit, which gross rows drag. A robust fit has left them out already.

    Returns
    -------
    tuple of int
        The poses, ascending.
    """
    x0 = np.zeros(len(problem.names))
    counts = _measured_counts(problem)
    e2 = _squared(problem, x0, w, counts)
    listed = _judge(e2, known, len(x0), np.zeros(len(e2), dtype=bool), counts)
    if not refit or not x0.size or not listed.size or 2 * listed.size > len(e2):
        return tuple(int(i) for i in listed)
    full = problem.reduced(x0)  # the fit's own: memoised, no pass over the poses
    if full.R.shape[0] < len(x0) or not np.all(np.abs(np.diag(full.R)) > 0):
        return tuple(int(i) for i in listed)  # a blind direction: no refit to judge by
    x = None
    for _ in range(REFITS):
        out = np.zeros(len(e2), dtype=bool)
        out[listed] = True
        e2, x = _without(problem, w, full, listed, x)
        e2 = _as_three(e2, counts)
        again = _judge(e2, known, len(x0), out, counts)
        if np.array_equal(again, listed) or not again.size or 2 * again.size > len(e2):
            break
        listed = again
    return tuple(int(i) for i in again)


def _squared(problem: Problem, x: np.ndarray, w: np.ndarray, counts=None) -> np.ndarray:
    """Squared σ-weighted point-residual norms at `x`, shape (N, m) (as χ²(3), `_as_three`,
    where `counts` says a point has fewer measured coordinates)."""
    e2 = np.sum((problem.point_residuals(x) * w[:, None, :]) ** 2, axis=2)
    return e2 if counts is None else _as_three(e2, counts)


def _measured_counts(problem: Problem) -> np.ndarray | None:
    """(N, m): each point's measured coordinates, or None when all three are."""
    if problem._unmeasured is None:
        return None
    n = len(problem.q)
    return 3 - problem._unmeasured.reshape(n, problem.m, 3).sum(axis=2)


def _as_three(e2: np.ndarray, counts) -> np.ndarray:
    """`e2` of points with `counts` measured coordinates (χ²(count) for noise) as the
    χ²(3) value of the same tail: a plane's one coordinate judged like three."""
    if counts is None:
        return e2
    from scipy.special import chdtrc, chdtri

    # in units of the noise the medians say (σ² unknown, or the residuals' own), so
    # that the tails are those of the noise; back in `e2`'s units after
    scales = [np.median(e2[counts == k]) / chdtri(k, 0.5) for k in (1, 2, 3) if np.any(counts == k)]
    s2 = float(np.median(scales)) if scales else 0.0
    if not s2 > 0:
        return np.where(counts == 0, 0.0, e2)
    out = e2.copy()
    for k in (1, 2):
        where = counts == k
        if np.any(where):
            tail = np.clip(chdtrc(k, e2[where] / s2), 1e-300, 1.0)
            out[where] = s2 * chdtri(3, tail)
    out[counts == 0] = 0.0
    return out


def _judge(e2: np.ndarray, known: bool, k: int, out: np.ndarray, counts=None) -> np.ndarray:
    """Poses of `e2` (N, m) above the limit, the noise scaled from the poses not `out`."""
    from scipy.special import chdtri  # scipy loads slowly; only fits need it

    n, m = e2.shape
    kept = e2[~out]
    rows = 3 * kept.size if counts is None else int(counts[~out].sum())
    if rows <= k:
        return np.zeros(0, dtype=int)  # no redundancy: nothing can stand out
    # the median of the fit's residuals, which k of the rows' freedom went into, scales σ²
    s2 = float(np.median(kept)) / CHI2_3_MEDIAN * rows / (rows - k)
    if known:
        s2 = max(s2, 1.0)  # noise as stated, unless the residuals say it is larger
    tail = -np.expm1(np.log1p(-FALSE_ALARM) / (n * m))  # Šidák: any of n·m points
    limit = max(chdtri(3, tail) * s2, 0.0 if known else OUTLIER_MINIMUM**2)
    return np.flatnonzero(e2.max(axis=1) > limit)


def _without(problem, w, full, listed, before) -> tuple[np.ndarray, np.ndarray]:
    """Squared residual norms (N, m) of the fit without the poses `listed`, and the
    refit's deviations (`before`: the previous refit's, or None).

    The others' are residuals; the listed ones' are prediction errors in units of their
    variance, ``rᵀ (I + Jₚ C Jₚᵀ)⁻¹ r`` with C the refit's covariance, each judged as a
    new pose would be. The refit is the linear model of the whole fit (`full`, its R
    factor) less the listed rows ``[A | a]``: with ``B = A R⁻¹``, ``JᵀJ`` less ``AᵀA`` is
    ``Rᵀ (I - BᵀB) R``, whose middle factor is as well conditioned as the listed rows
    leave the fit, so no normal equations square the condition number of R.
    """
    from scipy.linalg import solve_triangular

    x0 = np.zeros(len(problem.names))
    sub = problem.subset(listed)
    A, a = sub.jacobian(x0), sub.residual(x0)
    B = solve_triangular(full.R, A.T, trans="T").T  # A R⁻¹
    M = np.linalg.pinv(np.eye(len(x0)) - B.T @ B, rcond=1e-12, hermitian=True)
    u = full.Qtr - B.T @ a
    x = solve_triangular(full.R, M @ u)
    predicted = full.rr - float(a @ a) - float(u @ M @ u)  # the linear model's, the rest
    x = _settle(problem, listed, x, predicted, before)
    e2 = _squared(problem, x, w)
    points = B.reshape(len(listed), -1, len(x0))[:, : 3 * problem.m]  # Jₚ R⁻¹ of points
    res = problem.point_residuals(x)[listed] * w[listed, None, :]
    for i, pose in enumerate(listed):
        for j in range(problem.m):
            Bp = points[i, 3 * j : 3 * j + 3]
            e2[pose, j] = res[i, j] @ np.linalg.solve(np.eye(3) + Bp @ M @ Bp.T, res[i, j])
    return e2, x


def _settle(problem: Problem, listed, x: np.ndarray, predicted: float, before) -> np.ndarray:
    """The refit without the `listed` poses: `x`, where its cost lies within one noise
    variance of what the linear model `predicted` (and below the cost at `before`, the
    previous refit's end); else Levenberg-Marquardt from the lower of the two (a far gross
    error dragged the fit beyond where it is linear)."""
    keep = np.ones((len(problem.q), problem.m))
    keep[listed] = 0.0
    rest = problem.reweighted(keep)

    def cost(at):
        r = rest.residual(at)
        return float(r @ r)

    here = cost(x)
    there = np.inf if before is None else cost(before)
    if abs(here - predicted) <= here / max(np.count_nonzero(rest.w_flat) - x.size, 1):
        if here <= there:
            return x
    start = before if there < here else x
    return SOLVERS["lm"](rest, start, max_iterations=SETTLE_ITERATIONS, tolerance=1e-10)[0]
