"""What held-out validations share: the error statistics and which audit checks a refit of
frames must pass (`casecal.identification.validation`, `camera_validation`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import CalibrationError

CONVERGENCE_CHECKS = ("converged", "residual did not grow")
"""The checks a refit of frames alone must pass: the nominal robot's frames cannot fit to
the noise (its own errors remain), which is what a validation measures."""


@dataclass(frozen=True)
class ErrorStats:
    """Errors of a model on some measurements (one entry per measured point or corner):
    RMS, mean and largest length, in the residuals' unit (m; px for a camera's corners)."""

    rms: float
    mean: float
    max: float
    n_points: int

    @classmethod
    def of(cls, residuals: np.ndarray, dim: int = 3) -> ErrorStats:
        """From residual vectors (..., `dim`); rows not finite (corners not found) left out."""
        e = np.linalg.norm(np.asarray(residuals).reshape(-1, dim), axis=1)
        e = e[np.isfinite(e)]
        return cls(float(np.sqrt(np.mean(e**2))), float(e.mean()), float(e.max()), e.size)


def refitted(fit, what: str, where: str, hint: str = ""):
    """``fit()``, a `Calibration` of `what` (frames) alone on `where` (held-out data),
    refused when it cannot be made or did not converge (`CONVERGENCE_CHECKS`)."""
    try:
        cal = fit()
    except CalibrationError as exc:
        raise CalibrationError(f"cannot refit {what} to {where} ({exc}){hint}") from None
    failed = [c for c in cal.audit.failures if c.name in CONVERGENCE_CHECKS]
    if failed:
        raise CalibrationError(f"{what} did not fit {where}: {failed[0].name}: {failed[0].text}")
    return cal
