"""Poses whose residuals stand out from the others: listed, and left out of robust fits."""

from __future__ import annotations

import numpy as np

from .problem import Problem

OUTLIER_THRESHOLD = 5.0
"""Robust standard deviations (1.4826 MAD) above the median that make a pose stand out."""

OUTLIER_MINIMUM = {True: 4.0, False: 1e-9}
"""Residual norm a pose must also exceed to be listed: 4 σ with a stated σ (a 3-D
Gaussian norm passes it once in a thousand), else 1 nm (below it, residuals are rounding)."""


def outlier_poses(problem: Problem, w: np.ndarray, known: bool) -> tuple[int, ...]:
    """Poses whose largest point residual stands out from the others.

    A pose is listed when its largest (σ-weighted) point-residual norm lies more than
    `OUTLIER_THRESHOLD` robust standard deviations above the median of all poses, and
    above `OUTLIER_MINIMUM`. The norm of Gaussian noise in 3-D has a long right tail,
    hence 5 rather than 3.
    """
    e = np.linalg.norm(
        problem.point_residuals(np.zeros(len(problem.names))) * w[:, None, :], axis=2
    ).max(axis=1)
    med = np.median(e)
    spread = 1.4826 * np.median(np.abs(e - med))
    limit = max(med + OUTLIER_THRESHOLD * spread, OUTLIER_MINIMUM[known])
    return tuple(int(i) for i in np.flatnonzero(e > limit))
