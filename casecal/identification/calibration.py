"""The result of an identification: `Calibration`, its parameter table and its summary."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
import scipy.stats

from ..model.parameters import is_length, unit
from ..model.robot import Robot
from .analysis import Observability

# casecal statuses, one table for every method (scipy style: success = status > 0)
STATUS_MESSAGES = {
    -1: "failed: the solver reported an error",
    0: "stopped: maximum number of iterations reached",
    1: "done: one-shot linearised solution (the paper's SVD step)",
    2: "converged: the step fell below the tolerance",
    3: "stopped: the cost no longer decreases",
    4: "converged: residuals are at the rounding floor of the data",
    5: "converged: the solver's optimality tolerance was met",
}


POORLY_DETERMINED = {"m": 1e-3, "rad": math.radians(0.1)}
"""Standard errors above these (1 mm, 0.1°) mark an estimate the data barely constrain:
no industrial arm is calibrated usefully with a parameter that uncertain."""


def display_unit(name: str) -> tuple[str, float]:
    """Unit and factor from SI for tables: ("mm", 1e3) for lengths, ("deg", 180/π) for angles."""
    return ("mm", 1e3) if is_length(name) else ("deg", 180.0 / math.pi)


def _rms(residuals: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(residuals**2, axis=1))))


def _max(residuals: np.ndarray) -> float:
    return float(np.max(np.linalg.norm(residuals, axis=1)))


@dataclass(frozen=True)
class Calibration:
    """Identified parameter deviations, their uncertainty, and how the fit went.

    One type for every method (``"svd"``, ``"gauss-newton"``, ``"lm"``, ``"ipopt"``).
    All numbers are SI (m, rad); `table` and `summary` show mm and degrees.

    Attributes
    ----------
    method : str
    nominal, robot : Robot
        The robot before and after calibration.
    parameters : tuple of str
        The parameters asked for.
    estimated : tuple of str
        Those actually estimated: a base set of the identifiable ones. The others are held
        at nominal (deviation 0, standard error NaN) and listed in `unidentifiable`.
    deviations : dict of str to float
        Identified deviation of every asked-for parameter, SI.
    standard_errors : dict of str to float
        One standard deviation of each estimate, SI; NaN for parameters held at nominal.
    covariance : ndarray, shape (len(estimated), len(estimated))
        Covariance of the estimated deviations, SI. From the stated measurement σ when
        there is one, else scaled by the residual variance ``RSS / (3N - k)``.
    residuals, residuals_before : ndarray, shape (N · m, 3)
        Measured minus modelled positions after and before calibration, m (one row per
        measured point; m = 1 point per pose by default).
    orientation_residuals : ndarray, shape (N, 3), or None
        ``log(R_meas R_modelᵀ)`` after calibration, rad, when orientations were measured.
    outliers : tuple of int
        Poses (0-based rows) whose residuals stand out (see `identify`).
    loss : str
        The loss that was minimised.
    iterations : int
    status : int
        See `STATUS_MESSAGES`; ``success = status > 0``.
    message : str
    history : tuple of float
        Cost ``0.5 Σ (r/σ)²`` (or ``0.5 Σ r²`` in m² without σ) at the start and after
        each iteration.
    observability : Observability
        Of the asked-for parameters at the nominal robot and these poses.
    sigma_known : bool
        Whether the covariance uses a stated σ (True) or the residuals' own scale.
    truth : dict or None
        True deviations (SI), when known (simulation); adds columns to `table`.
    """

    method: str
    nominal: Robot
    robot: Robot
    parameters: tuple[str, ...]
    estimated: tuple[str, ...]
    deviations: dict
    standard_errors: dict
    covariance: np.ndarray
    residuals: np.ndarray
    residuals_before: np.ndarray
    iterations: int
    status: int
    message: str
    history: tuple[float, ...]
    observability: Observability
    sigma_known: bool
    truth: dict | None = None
    wall_time: float = field(default=0.0, compare=False)
    start_note: str = ""
    orientation_residuals: np.ndarray | None = None
    outliers: tuple[int, ...] = ()
    loss: str = "linear"

    @property
    def success(self) -> bool:
        """True when the method reached a solution (status > 0)."""
        return self.status > 0

    @property
    def unidentifiable(self) -> tuple[str, ...]:
        """Asked-for parameters the data cannot see individually (held at nominal or
        standing for a combination)."""
        return self.observability.unidentifiable

    @property
    def held(self) -> tuple[str, ...]:
        """Asked-for parameters held at nominal because the data cannot separate them."""
        return tuple(n for n in self.parameters if n not in self.estimated)

    @property
    def n_poses(self) -> int:
        """Number of poses N."""
        return self.observability.n_poses

    @property
    def rms(self) -> float:
        """RMS position error after calibration, m: ``sqrt(mean |r_i|²)``."""
        return _rms(self.residuals)

    @property
    def max_error(self) -> float:
        """Largest position error after calibration, m."""
        return _max(self.residuals)

    @property
    def rms_before(self) -> float:
        """RMS position error of the nominal robot, m."""
        return _rms(self.residuals_before)

    @property
    def max_error_before(self) -> float:
        """Largest position error of the nominal robot, m."""
        return _max(self.residuals_before)

    @property
    def poorly_determined(self) -> tuple[str, ...]:
        """Estimated parameters whose standard error exceeds `POORLY_DETERMINED`."""
        return tuple(
            n for n in self.estimated if not self.standard_errors[n] <= POORLY_DETERMINED[unit(n)]
        )

    @property
    def reduced_chi2(self) -> float:
        """Σ (r/σ)² / dof at the solution: about 1 when model and stated σ are right; NaN
        without a stated σ or residual degrees of freedom."""
        if not self.sigma_known or self.dof_residual <= 0:
            return float("nan")
        return 2.0 * self.history[-1] / self.dof_residual

    @property
    def dof_residual(self) -> int:
        """Residual degrees of freedom: measured coordinates − k."""
        rows = self.residuals.size + (
            0 if self.orientation_residuals is None else self.orientation_residuals.size
        )
        return rows - len(self.estimated)

    def compare_to(self, truth: dict) -> Calibration:
        """The same result with the true deviations (SI) known: `table` gains error columns."""
        unknown = [n for n in truth if n not in self.nominal.parameters]
        if unknown:
            from ..errors import CalibrationError

            raise CalibrationError(f"truth names unknown parameter {unknown[0]!r}")
        return dataclasses.replace(self, truth={k: float(v) for k, v in truth.items()})

    def errors(self) -> dict:
        """Relative error of each identified deviation, ``(identified - true) / |true|``.

        Only for parameters with a non-zero true deviation that were estimated.
        """
        if not self.truth:
            return {}
        return {
            n: (self.deviations[n] - t) / abs(t)
            for n, t in self.truth.items()
            if t != 0 and n in self.estimated
        }

    @property
    def table(self) -> pd.DataFrame:
        """One row per asked-for parameter, in mm and degrees.

        Columns: parameter, unit, nominal, deviation, std_error, ci95_low, ci95_high,
        status; with `truth`: synthetic, error_pct (``100 (identified - true) / |true|``).
        """
        if self.sigma_known:
            z = scipy.stats.norm.ppf(0.975)
        else:
            z = scipy.stats.t.ppf(0.975, max(self.dof_residual, 1))
        combos = {m: spot for spot in self.observability.blind_spots for m in spot.members}
        rows = []
        nominal = self.nominal.parameters
        for name in self.parameters:
            u, f = display_unit(name)
            dev, se = self.deviations[name], self.standard_errors[name]
            if name not in self.estimated:
                status = "held: unidentifiable" + ("" if dev == 0 else " (at its start value)")
            elif name in combos:
                spot = combos[name]
                meaning = spot.visible_as(name)
                status = f"stands for {meaning}" if meaning else "blind combination"
                if se > POORLY_DETERMINED[unit(name)]:
                    status += ", poorly determined"
            elif se > POORLY_DETERMINED[unit(name)]:
                status = "poorly determined"
            else:
                status = "identified"
            row = {
                "parameter": name,
                "unit": u,
                "nominal": nominal[name] * f,
                "deviation": dev * f,
                "std_error": se * f,
                "ci95_low": (dev - z * se) * f,
                "ci95_high": (dev + z * se) * f,
                "status": status,
            }
            if self.truth is not None:
                true = self.truth.get(name, 0.0)
                row["synthetic"] = true * f
                row["error_pct"] = 100 * (dev - true) / abs(true) if true else math.nan
            rows.append(row)
        return pd.DataFrame(rows)

    def summary(self) -> Summary:
        """A readable report: header, parameter table (mm, deg), observability, notes."""
        from .summary import build_summary

        return build_summary(self)


@dataclass(frozen=True)
class Summary:
    """Text report of a `Calibration`; ``str(summary)`` gives it, `to_frame` the table."""

    header: str
    table: pd.DataFrame
    diagnostics: str
    notes: tuple[str, ...]

    def as_text(self) -> str:
        """The whole report as plain text."""
        from .summary import format_table

        parts = [self.header, format_table(self.table), self.diagnostics]
        if self.notes:
            parts.append("Notes:\n" + "\n".join(f"[{i}] {n}" for i, n in enumerate(self.notes, 1)))
        return "\n\n".join(parts)

    def to_frame(self) -> pd.DataFrame:
        """The parameter table as a DataFrame (mm, deg)."""
        return self.table.copy()

    def __str__(self) -> str:
        return self.as_text()
