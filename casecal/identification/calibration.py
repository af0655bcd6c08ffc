"""The result of an identification: `Calibration`, its parameter table and its summary."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from ..model.parameters import UNITS, unit
from ..model.robot import Robot
from .analysis import Observability, Representation
from .audit import Audit

if TYPE_CHECKING:
    import pandas as pd

# casecal statuses, one table for every method (scipy style: success = status > 0)
STATUS_MESSAGES = {
    -2: "failed: the answer audit did not pass",
    -1: "failed: the solver reported an error",
    0: "stopped: maximum number of iterations reached",
    1: "done: one-shot linearised solution (the paper's SVD step)",
    2: "converged: the step fell below the tolerance",
    3: "stopped: the cost no longer decreases",
    4: "converged: residuals are at the rounding floor of the data",
    5: "converged: the solver's optimality tolerance was met",
    6: "converged: the solver stopped early, at a point no step can measurably improve",
}


def display_unit(name: str) -> tuple[str, float]:
    """Unit and factor from SI for tables: ("mm", 1e3) for lengths, ("deg", 180/π) for
    angles (`casecal.model.parameters.UNITS`)."""
    facts = UNITS[unit(name)]
    return facts.shown, facts.factor


def _rms(residuals: np.ndarray, unmeasured=None) -> float:
    if unmeasured is not None and unmeasured.shape == residuals.shape:
        n = max(int(np.count_nonzero(~unmeasured)), 1)
        return float(np.sqrt(3.0 * np.sum(residuals**2) / n))
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
        Those actually estimated: a base set of what the data determine. The others are
        held at nominal (deviation 0, standard error NaN): blind at these poses, or not
        determined by these data (`pruned`); see `held_reason`.
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
    outliers_lead : bool
        A failed fit's message leads with `outliers`: they are few (`summary.FEW`), so a
        gross value in them is the likelier cause than a model error.
    loss : str
        The loss that was minimised.
    iterations : int
    status : int
        See `STATUS_MESSAGES`; ``success = status > 0``. -2 when the answer audit
        failed, whatever the solver said (`solver_status`).
    message : str
    history : tuple of float
        Cost ``0.5 Σ (r/σ)²`` (or ``0.5 Σ r²`` in m² without σ) at the start and after
        each iteration.
    observability : Observability
        Of the asked-for parameters at these poses, where the fit ended.
    sigma_known : bool
        Whether the covariance uses a stated σ (True) or the residuals' own scale.
    truth : dict or None
        True deviations (SI), when known (simulation); adds columns to `table`.
    audit : Audit or None
        The checks that decided `status` (`casecal.identification.audit`).
    solver_status : int or None
        What the solver itself reported, before the audit.
    representation : Representation or None
        What each estimate stands for when it also carries held parameters' effects
        (e.g. ``d2`` for ``d2 + d3 + d4``).
    pruned : dict of str to str
        Parameters held because these data do not determine them, with the reason.
    frozen : dict of str to str
        Parameters that were estimated in an earlier round but are blind where the fit
        ended: held at the value they were fitted to while visible (their deviation need
        not be zero), with the reason.
    start_observability : Observability or None
        Of the asked-for parameters where the fit started.
    rounds : int
        Rounds of fit-and-look-again (`casecal.identification.rounds`).
    joined : tuple of str
        Parameters blind where the fit started that the later rounds estimated.
    pose_blind : tuple of str
        Held parameters that are blind at these poses only: poses across the joint
        ranges would tell them apart. The calibrated robot is then right on poses like
        the measured ones, and elsewhere shows these parameters' own (unknown) deviations;
        the answer audit fails such a fit.
    still_joints : tuple of str
        Joints that barely move in the data (under 1° or 1 mm), with their value.
    measured : {"points", "distances", "pixels"}
        What the residuals are: measured points (N·m rows of x, y, z), distances between
        pairs of poses (one row each), or a camera's pixels (one row per corner: the pixel
        error seen at the board's distance, m, in x and y; z not measured).
    sessions : dict of str to SessionFit
        For measurements of several sessions (`Measurements.session`): each session's
        fitted frames with their standard errors, by label in order of appearance
        (`casecal.identification.sessions.SessionFit`). `robot` has the first session's
        frames; `nominal` has a frame per session, all at the nominal ones. Empty for one
        session.
    unmeasured : ndarray of bool, shape (N·m, 3), optional
        True for coordinates not measured (σ inf: a plane's x and y, see
        `casecal.identification.contact`); their residuals are 0 and count nowhere. None
        when every coordinate was measured.
    camera : casecal.identification.camera_fit.CameraFit or None
        For camera measurements: the fitted camera and board poses, the lens, the pixel
        residuals (px).
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
    outliers_lead: bool = False
    loss: str = "linear"
    audit: Audit | None = None
    solver_status: int | None = None
    representation: Representation | None = None
    pruned: dict = field(default_factory=dict)
    frozen: dict = field(default_factory=dict)
    start_observability: Observability | None = None
    rounds: int = 1
    joined: tuple[str, ...] = ()
    pose_blind: tuple[str, ...] = ()
    still_joints: tuple[str, ...] = ()
    measured: str = "points"
    sessions: dict = field(default_factory=dict)
    unmeasured: np.ndarray | None = None
    camera: object | None = None

    @property
    def success(self) -> bool:
        """True when the method reached a solution (status > 0)."""
        return self.status > 0

    @property
    def unidentifiable(self) -> tuple[str, ...]:
        """Asked-for parameters the data cannot determine individually: those held (blind
        at these poses, or not determined for the noise) and the estimates that stand for
        a combination with held ones."""
        combined = {n for n in self.estimated if self._terms().get(n)}
        return tuple(n for n in self.parameters if n not in self.estimated or n in combined)

    @property
    def held(self) -> tuple[str, ...]:
        """Asked-for parameters held at nominal (not estimated); `held_reason` says why."""
        return tuple(n for n in self.parameters if n not in self.estimated)

    def held_reason(self, name: str) -> str:
        """Why a held parameter was not estimated, in words ("" for an estimated one)."""
        if name in self.estimated:
            return ""
        if name in self.pruned:
            return "not determined by these data: " + self.pruned[name]
        if name in self.frozen:
            return self.frozen[name]
        carriers = [e for e, terms in self._terms().items() if any(h == name for h, _ in terms)]
        if carriers:
            shown = "; ".join(self.stands_for(e) for e in carriers)
            return f"blind: its effect is carried by {shown}"
        return "it moves nothing measured at these poses"

    def _terms(self) -> dict:
        return {} if self.representation is None else self.representation.terms

    def stands_for(self, name: str) -> str:
        """What the estimate of `name` means: ``name`` itself, or a combination such as
        ``"d2 + d3 + d4"`` when held parameters' effects are carried by it."""
        if self.representation is None:
            return name
        return self.representation.expression(name)

    def true_value(self, name: str) -> float | None:
        """The true value (SI) of what `name`'s estimate stands for; None without truth."""
        if self.truth is None:
            return None
        if name in self.estimated and self.representation is not None:
            return self.representation.combination(name, self.truth)
        return self.truth.get(name, 0.0)

    @property
    def n_poses(self) -> int:
        """Number of poses N."""
        return self.observability.n_poses

    @property
    def rms(self) -> float:
        """RMS position error after calibration, m: ``sqrt(mean |r_i|²)`` (with coordinates
        not measured, √3 × the RMS of the measured ones)."""
        return _rms(self.residuals, self.unmeasured)

    @property
    def max_error(self) -> float:
        """Largest position error after calibration, m."""
        return _max(self.residuals)

    @property
    def rms_before(self) -> float:
        """RMS position error of the nominal robot, m."""
        return _rms(self.residuals_before, self.unmeasured)

    @property
    def max_error_before(self) -> float:
        """Largest position error of the nominal robot, m."""
        return _max(self.residuals_before)

    @property
    def poorly_determined(self) -> tuple[str, ...]:
        """Estimated parameters whose standard error exceeds its unit's `poorly` bound:
        the nominal robot's (`casecal.Robot.sizes`), by default
        `casecal.model.parameters.UNITS`' (1 mm, 0.1°)."""
        return tuple(
            n
            for n in self.estimated
            if not self.standard_errors[n] <= self.nominal.unit_facts(n).poorly
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
        points = self.residuals.size
        if self.unmeasured is not None and self.unmeasured.shape == self.residuals.shape:
            points = int(np.count_nonzero(~self.unmeasured))
        rows = points + (
            0 if self.orientation_residuals is None else self.orientation_residuals.size
        )
        return rows - len(self.estimated)

    def session_robot(self, label: str) -> Robot:
        """The calibrated robot as session `label` saw it: with that session's fitted base
        (and tool) frame, to predict its measurements in its instrument's frame."""
        if label not in self.sessions:
            from ..errors import CalibrationError

            known = ", ".join(self.sessions) or "none: the data had one session"
            raise CalibrationError(f"no session {label!r} in this calibration (sessions: {known})")
        fit = self.sessions[label]
        tool = self.robot.tool if fit.tool is None else fit.tool
        return dataclasses.replace(self.robot, base=fit.base, tool=tool, auto_beta=False)

    def compare_to(self, truth: dict) -> Calibration:
        """The same result with the true deviations (SI) known: `table` gains error columns."""
        unknown = [n for n in truth if n not in self.nominal.parameters]
        if unknown:
            from ..errors import CalibrationError

            raise CalibrationError(f"truth names unknown parameter {unknown[0]!r}")
        return dataclasses.replace(self, truth={k: float(v) for k, v in truth.items()})

    def errors(self) -> dict:
        """Relative error of each estimate, ``(identified - true) / |true|``.

        Only for estimated parameters whose true value is not zero. An estimate that stands
        for a combination (``d2`` for ``d2 + d3 + d4``) is compared with the true value of
        that combination: what the data could identify, not a split they cannot see.
        """
        if not self.truth:
            return {}
        out = {}
        for n in self.estimated:
            true = self.true_value(n)
            if true:
                out[n] = (self.deviations[n] - true) / abs(true)
        return out

    @property
    def table(self) -> pd.DataFrame:
        """One row per asked-for parameter, in mm and degrees.

        Columns: parameter, unit, nominal, deviation, std_error, ci95_low, ci95_high,
        status; with `truth`: synthetic, error_pct (``100 (identified - true) / |true|``).
        A row whose estimate stands for a combination gives that combination's value,
        interval and truth; a held row has no interval and no error.
        """
        import pandas as pd  # only here: `identify` need not load it

        if self.sigma_known:
            z = 1.959963984540054  # the standard normal's 97.5 % quantile
        else:
            from scipy.special import stdtrit  # Student's t quantile; scipy loads slowly

            z = float(stdtrit(max(self.dof_residual, 1), 0.975))
        rows = []
        nominal = self.nominal.parameters
        for name in self.parameters:
            u, f = display_unit(name)
            dev, se = self.deviations[name], self.standard_errors[name]
            if name not in self.estimated:
                status = "held: " + self.held_reason(name)
            else:
                meaning = self.stands_for(name)
                status = "identified" if meaning == name else f"stands for {meaning}"
                if se > self.nominal.unit_facts(name).poorly:
                    status = (
                        "poorly determined" if meaning == name else status + ", poorly determined"
                    )
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
                true = self.true_value(name)
                row["synthetic"] = true * f
                row["error_pct"] = (
                    100 * (dev - true) / abs(true) if true and name in self.estimated else math.nan
                )
            rows.append(row)
        return pd.DataFrame(rows)

    def to_dict(self) -> dict:
        """This result as one JSON-ready dict, units in the key names
        (`casecal.identification.result_dict.calibration_dict`; keys in the README)."""
        from .result_dict import calibration_dict

        return calibration_dict(self)

    def residual_table(self) -> pd.DataFrame:
        """One row per measured point: pose, error before and after in mm, outlier flag
        (`casecal.identification.result_dict.residual_rows`)."""
        from .result_dict import residual_rows

        return residual_rows(self)

    def summary(self) -> Summary:
        """A readable report: header, parameter table (mm, deg), observability, notes."""
        from .summary import build_summary

        return build_summary(self)


@dataclass(frozen=True)
class Summary:
    """Text report of a `Calibration`; ``str(summary)`` gives it, `to_frame` the table;
    `sessions` the fitted frames of measurements of several sessions ("" for one)."""

    header: str
    table: pd.DataFrame
    diagnostics: str
    notes: tuple[str, ...]
    sessions: str = ""

    def as_text(self) -> str:
        """The whole report as plain text."""
        from .summary import format_table

        parts = [self.header, format_table(self.table), self.diagnostics]
        if self.sessions:
            parts.insert(2, self.sessions)
        if self.notes:
            parts.append("Notes:\n" + "\n".join(f"[{i}] {n}" for i, n in enumerate(self.notes, 1)))
        return "\n\n".join(parts)

    def to_frame(self) -> pd.DataFrame:
        """The parameter table as a DataFrame (mm, deg)."""
        return self.table.copy()

    def __str__(self) -> str:
        return self.as_text()
