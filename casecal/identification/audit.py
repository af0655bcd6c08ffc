"""The answer audit: the checks a fit must pass before casecal calls it a success.

A calibration tool's worst failure is a confident wrong robot. Whether an estimate is right
cannot be seen from the data alone, but these can, and each failing one makes the fit a
failure with its reason:

- **converged**: no further Gauss-Newton step could lower the cost measurably (by more
  than `OPTIMALITY` of a noise variance), whatever the solver reported; for the paper's one-shot
  ``"svd"`` without a stated σ, one that would move the fit by less than
  `RESOLUTION` RMS (its linearisation error is below what any instrument resolves);
- **residual did not grow**: the fit is no worse than where it started;
- **residual consistent with the noise**: with a stated σ, the reduced χ² is within the
  99.9 % bound of chance, allowing σ to be 10 % low; without one, the RMS residual is
  within what any position instrument's noise explains (`PLAUSIBLE_NOISE`); either way,
  the residuals are not smooth in the joint values (`smoothness`): noise differs from one
  pose to the next, a model error does not;
- **prediction**: the error the covariance predicts on new poses within the joint limits
  is not larger than the error the robot had before calibration, and no parameter had to
  be held because its uncertainty alone would exceed that error (what the other
  estimates absorbed of it then holds only on poses like the measured ones): poses that
  cannot support the parameters make the robot worse elsewhere, and say so here;
- **held parameters do not matter**: freeing the parameters held because the data did not
  determine them would lower the cost by no more than chance allows (a χ² quantile,
  `casecal.identification.rank.held_matter`, in noise variances or, without σ, residual
  variances): otherwise the data do see them, and what looked like noise is a parameter
  missing from the fit;
- **identifiable set settled**: the rounds of `casecal.identification.rounds` stopped
  changing which parameters they estimate.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..design.poses import uniform
from ..errors import CalibrationError
from ..model import kinematics
from ..model.robot import Robot
from .rank import chi2_quantile, held_matter

OPTIMALITY = 0.5
"""Largest cost decrease one more step may still promise, in noise variances: the fit is
then within one standard error (Mahalanobis distance √(2·0.5)) of the least-squares
minimum in every direction, which no one could tell from the minimum itself. Along a
nearly blind direction the linearised promise is often not even realisable; fits that
really stalled promise tens to thousands."""

SIGMA_SLACK = 1.1
"""The stated σ may be this much too small before the residuals count as too large."""

CHI2_LEVEL = 0.999
"""Quantile of χ² beyond which residuals are not chance."""

PLAUSIBLE_NOISE = 1e-3
"""RMS residual (m) beyond which, with no σ stated, the residuals are taken for a model
that does not fit rather than for instrument noise."""

RESOLUTION = 1e-6
"""RMS change of the fitted points (m) below which the one-shot method's linearisation
error counts as converged when no σ is stated: below a laser tracker's resolution."""

PREDICTION_POSES = 200

SMOOTH = 0.5
"""Below this `smoothness`, the residuals of neighbouring poses are too alike for noise."""

SMOOTHNESS_POSES = 2000


@dataclass(frozen=True)
class Check:
    """One line of the audit.

    Attributes
    ----------
    name : str
    passed : bool or None
        None when the check does not apply (e.g. no σ stated for the χ² test).
    text : str
        What was measured, with units.
    """

    name: str
    passed: bool | None
    text: str

    def __post_init__(self) -> None:
        if self.passed is not None:  # numpy's bool is not `False`: keep `is` tests honest
            object.__setattr__(self, "passed", bool(self.passed))


@dataclass(frozen=True)
class Audit:
    """The checks of one fit (module doc); ``passed`` when none failed."""

    checks: tuple[Check, ...]

    @property
    def passed(self) -> bool:
        return all(c.passed is not False for c in self.checks)

    @property
    def failures(self) -> tuple[Check, ...]:
        return tuple(c for c in self.checks if c.passed is False)

    def lines(self) -> list[str]:
        """One line per check: ``ok``, ``FAIL`` or ``n/a``, the check, what was measured."""
        mark = {True: "ok  ", False: "FAIL", None: "n/a "}
        return [f"{mark[c.passed]} {c.name}: {c.text}" for c in self.checks]


@dataclass(frozen=True)
class Facts:
    """What the audit looks at, gathered by `casecal.identify`.

    Costs are ``0.5 Σ (r/σ)²`` (or ``0.5 Σ r²`` in m² without σ); RMS values in m.
    """

    solver_status: int
    solver_message: str | None
    cost_start: float
    cost_final: float
    floor: float
    predicted_decrease: float
    known: bool
    dof: int
    rms_start: float
    rms_final: float
    settled: bool
    rounds: int
    predicted_rms: float | None
    n_points: int = 1
    one_shot: bool = False
    unsupported: tuple[str, ...] = ()
    held_gain: float = 0.0
    held: tuple[str, ...] = ()
    smoothness: float | None = None
    prediction_note: str = ""


def audit(f: Facts) -> Audit:
    """Run the checks of the module doc on `f`."""
    return Audit(
        (
            _converged(f),
            _no_growth(f),
            _noise(f),
            _prediction(f),
            _held(f),
            Check(
                "identifiable set settled",
                f.settled,
                f"after {f.rounds} round{'s' * (f.rounds != 1)}"
                if f.settled
                else f"the estimated set still changed after {f.rounds} rounds",
            ),
        )
    )


def _converged(f: Facts) -> Check:
    if f.solver_status < 0:
        return Check("converged", False, f.solver_message or "the solver reported an error")
    scale = 1.0 if f.known else (2.0 * f.cost_final / f.dof if f.dof > 0 else 1.0)
    limit = OPTIMALITY * scale + f.floor
    unit = "noise variances" if f.known else "residual variances"
    text = (
        f"one more step would lower the cost by {f.predicted_decrease / scale:.2g} {unit} "
        f"(limit {OPTIMALITY:g})"
        if f.cost_final > f.floor
        else "residuals at the rounding floor of the data"
    )
    if f.one_shot and not f.known:
        moved = np.sqrt(2.0 * f.predicted_decrease / max(f.n_points, 1))
        limit = max(limit, 0.5 * RESOLUTION**2 * f.n_points)
        text = (
            f"one more step would move the fitted points by {moved * 1e3:.2g} mm RMS "
            f"(one-shot method, no σ: limit {RESOLUTION * 1e3:g} mm, an instrument's resolution)"
        )
    ok = f.predicted_decrease <= limit
    if not ok:
        text += (
            ": the fit stopped before the minimum (a nearly flat valley: more iterations "
            "with --max-iterations, or more, better-spread poses)"
        )
    return Check("converged", ok, text)


def _no_growth(f: Facts) -> Check:
    ok = f.cost_final <= f.cost_start * (1 + 1e-9) + f.floor
    text = f"RMS {f.rms_start * 1e3:.4g} mm at the start, {f.rms_final * 1e3:.4g} mm after"
    if not ok:
        text += (
            ": the fit made the residuals larger (a one-shot linearisation far from the "
            "truth; use an iterated method)"
        )
    return Check("residual did not grow", ok, text)


def _noise(f: Facts) -> Check:
    name = "residual consistent with the noise"
    if f.known:
        if f.dof <= 0:
            return Check(name, None, "no residual degrees of freedom")
        chi2 = 2.0 * f.cost_final / f.dof
        bound = SIGMA_SLACK**2 * chi2_quantile(CHI2_LEVEL, f.dof) / f.dof
        ok = chi2 <= bound
        text = f"reduced χ² = {chi2:.3g} (bound {bound:.3g}; residuals {np.sqrt(chi2):.3g}× σ)"
        if not ok:
            text += (
                ": the model does not fit these data to their noise (a parameter missing "
                "from the set, a wrong frame, outliers, or a σ that is too small)"
            )
    else:
        ok = f.rms_final <= PLAUSIBLE_NOISE
        text = f"no σ stated; RMS residual {f.rms_final * 1e3:.4g} mm"
        if not ok:
            text += (
                f", more than any position instrument's noise ({PLAUSIBLE_NOISE * 1e3:g} mm): "
                "the model does not fit; if your instrument really is that noisy, state its "
                "σ (--noise, or a sigma_mm column) and the fit is judged against it"
            )
    at_floor = f.cost_final <= f.floor or (f.one_shot and f.rms_final <= RESOLUTION)
    if f.smoothness is not None and not at_floor:
        smooth = f.smoothness < SMOOTH
        text += f"; neighbouring poses' residuals differ {f.smoothness:.2f}× as much as noise's"
        if smooth:
            ok = False
            text += (
                " would: the residuals change smoothly with the joint values, a model error "
                "(a parameter missing or held, a fit stuck short of the minimum), not noise"
            )
    return Check(name, ok, text)


def smoothness(q: np.ndarray, residuals: np.ndarray, seed: int = 0) -> float | None:
    """How much the residuals of neighbouring poses differ, relative to independent noise.

    For each pose, the nearest other pose in joint space (joints scaled to the range they
    span in the data); the mean squared difference of their residual vectors over twice
    the mean squared residual. About 1 for noise, which is independent from pose to pose;
    near 0 for a model error, which changes smoothly with the joint values. None for fewer
    than 12 poses. At most `SMOOTHNESS_POSES` poses (a fixed random subset) are compared.

    Parameters
    ----------
    q : ndarray, shape (N, dof)
    residuals : ndarray, shape (N, ...)
        Each pose's residuals, any units.
    """
    n = q.shape[0]
    if n < 12:
        return None
    r = residuals.reshape(n, -1)
    if n > SMOOTHNESS_POSES:
        keep = np.random.default_rng(seed).choice(n, SMOOTHNESS_POSES, replace=False)
        q, r, n = q[keep], r[keep], SMOOTHNESS_POSES
    span = np.ptp(q, axis=0)
    z = (q - q.min(axis=0)) / np.where(span > 0, span, 1.0)
    d = np.sum((z[:, None, :] - z[None, :, :]) ** 2, axis=2)
    np.fill_diagonal(d, np.inf)
    nearest = np.argmin(d, axis=1)
    total = 2.0 * np.mean(np.sum(r**2, axis=1))
    if total == 0:
        return None
    return float(np.mean(np.sum((r - r[nearest]) ** 2, axis=1)) / total)


def _held(f: Facts) -> Check:
    name = "held parameters do not matter"
    if not f.held:
        return Check(name, None, "none held for the noise")
    scale = 1.0 if f.known else (2.0 * f.cost_final / f.dof if f.dof > 0 else 1.0)
    matter, gain, bound = held_matter(f.held_gain, len(f.held), scale)
    ok = not matter or f.cost_final <= f.floor
    text = (
        f"freeing {', '.join(f.held)} would lower the cost by {gain / 2:.3g} "
        f"{'noise' if f.known else 'residual'} variances (chance: up to {bound / 2:.3g})"
    )
    if not ok:
        text += (
            ": the data do see them; the residuals are a missing parameter, not noise "
            "(state the measurement σ, or measure better-spread poses)"
        )
    return Check(name, ok, text)


def _prediction(f: Facts) -> Check:
    name = "prediction no worse than uncalibrated"
    if f.unsupported:
        return Check(
            name,
            False,
            f"these poses cannot determine {', '.join(f.unsupported)} (their uncertainty "
            f"would exceed the uncalibrated error of {f.rms_start * 1e3:.3g} mm on poses "
            "across the workspace); held at nominal, but what the other estimates absorbed "
            "of them holds only on poses like the measured ones (measure more, "
            "better-spread poses, or ask for fewer parameters)",
        )
    if f.predicted_rms is None:
        return Check(name, None, f.prediction_note or "no joint limits to draw poses from")
    ok = f.predicted_rms <= max(f.rms_start, 1e-9)
    text = (
        f"predicted RMS error on {PREDICTION_POSES} new poses within the joint limits "
        f"{f.predicted_rms * 1e3:.3g} mm (from the covariance); uncalibrated "
        f"{f.rms_start * 1e3:.3g} mm"
    )
    if not ok:
        text += (
            ": these poses do not support the estimated parameters, and the calibrated "
            "robot would be worse than the nominal one away from them (measure more, "
            "better-spread poses, or ask for fewer parameters)"
        )
    return Check(name, ok, text)


def predicted_rms(robot: Robot, estimated, cov: np.ndarray, seed: int = 0) -> float | None:
    """RMS over `PREDICTION_POSES` uniform poses of the error the covariance predicts, m.

    The error of each measured point is Gaussian with covariance ``J C Jᵀ``; its mean
    square is ``trace(J C Jᵀ)``. None when the robot has no limits to draw poses from.
    """
    if not estimated:
        return 0.0
    try:
        q = uniform(robot, PREDICTION_POSES, seed=seed)
    except CalibrationError:
        return None
    chain = kinematics.chain(robot.structure)
    J = chain.evaluate("points_jacobian", q, robot.vector(), chain.columns(list(estimated)))
    mean_square = np.einsum("nik,kl,nil->", J, cov, J) / (J.shape[0] * J.shape[1] / 3)
    return float(np.sqrt(max(mean_square, 0.0)))
