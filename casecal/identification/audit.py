"""The answer audit: the checks a fit must pass before casecal calls it a success.

A calibration tool's worst failure is a confident wrong robot. Whether an estimate is right
cannot be seen from the data alone, but these can, and each failing one makes the fit a
failure with its reason:

- **converged**: no further Gauss-Newton step could lower the cost measurably (by more
  than `OPTIMALITY` of a noise variance), whatever the solver reported; for the paper's one-shot
  ``"svd"`` without a stated σ, one that would move the fit by less than
  `RESOLUTION` RMS (its linearisation error is below what any instrument resolves);
- **residual did not grow**: the fit is no worse than where it started;
- **residual consistent with the noise**: some coordinates are left over to check the fit
  with (residual degrees of freedom); with a stated σ, the reduced χ² is within the
  99.9 % bounds of chance, allowing σ to be 10 % low or three times high (residuals at
  the rounding floor aside: noise-free data fit exactly); without one, the RMS residual is
  within what any position instrument's noise explains (`PLAUSIBLE_NOISE`); either way,
  the residuals are not smooth in the joint values (`smoothness`): noise differs from one
  pose to the next, a model error does not;
- **prediction**: the error the covariance predicts on new poses within the joint limits
  is not larger than the error the robot had before calibration, no parameter had to
  be held because its uncertainty alone would exceed that error, and none is blind at
  the measured poses that poses across the joint ranges would see (what the other
  estimates absorbed of it then holds only on poses like the measured ones): poses that
  cannot support the parameters make the robot worse elsewhere, and say so here;
- **held parameters do not matter**: freeing the parameters held because the data did not
  determine them would lower the cost by no more than chance allows (a χ² quantile,
  `casecal.identification.rank.held_matter`, in noise variances or, without σ, residual
  variances): otherwise the data do see them, and what looked like noise is a parameter
  missing from the fit;
- **parameters not asked for do not matter**: the same test for the robot's parameters
  outside the asked-for set (`casecal.identification.evidence.outside_gain`): a deviation
  of one of them, absorbed by the estimates, is a confident wrong robot;
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
from ..observations.rig import moves_robot
from .rank import chi2_quantile, held_matter

OPTIMALITY = 0.5
"""Largest cost decrease one more step may still promise, in noise variances: the fit is
then within one standard error (Mahalanobis distance √(2·0.5)) of the least-squares
minimum in every direction, which no one could tell from the minimum itself. Along a
nearly blind direction the linearised promise is often not even realisable; fits that
really stalled promise tens to thousands."""

SIGMA_SLACK = 1.1
"""The stated σ may be this much too small before the residuals count as too large."""

SIGMA_HIGH = 3.0
"""The stated σ may be this much too large before the residuals count as too small: a
conservative spec-sheet σ passes; a σ in millimetres given as metres does not. Too large a
σ lets the noise-aware rank hold parameters the data determine well (a 1000× σ held six
of 24 and left 0.78 mm where 0.011 mm was reachable)."""

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

NEGLIGIBLE_RMS = 1e-10
"""RMS residual (m) below which, with no σ stated, a fit counts as converged whatever one
more step promises: a tenth of a nanometre, below anything an instrument resolves."""


def listed(names, most: int = 8) -> str:
    """``"a, b, c"``; past `most` names, the first ones and how many in all."""
    names = list(names)
    if len(names) <= most:
        return ", ".join(names)
    return f"{', '.join(names[:most])} … ({len(names)} in all)"


CAUSES = (
    "robot keeps its size",  # casecal.identification.scale: a unit slip explains the rest
    "no bound decides an estimate",
    "parameters not asked for do not matter",
    "held parameters do not matter",
    "prediction no worse than uncalibrated",
)


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
    cause: bool = False
    """A failure that explains the others (a model error the residuals show): first in
    `Audit.failures`."""

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
        """The failed checks, causes first: a parameter missing or unsupported explains a
        residual too large for the noise or a fit that stalled, not the other way round."""
        failed = [c for c in self.checks if c.passed is False]
        return tuple(sorted(failed, key=lambda c: (not c.cause, c.name not in CAUSES)))

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
    correction_rms: float = 0.0
    """RMS distance (m) the fit moved the measured points by, at poses across the
    workspace: the uncalibrated error there plus the estimate's own error."""
    noise_rms: float = 0.0
    """Per-coordinate noise RMS (m): σ when stated, else the residual RMS; a predicted
    error below it is as good as the instrument can tell."""
    n_points: int = 1
    n_estimated: int = 0
    one_shot: bool = False
    unsupported: tuple[str, ...] = ()
    items: str = "poses"
    """What one measurement row group is, in words ("pairs" for distances)."""
    held_gain: float = 0.0
    held: tuple[str, ...] = ()
    smoothness: float | None = None
    prediction_note: str = ""
    blind_here: tuple[str, ...] = ()
    still: tuple[str, ...] = ()
    outside_gain: float = 0.0
    outside_visible: int = 0
    outside_leading: tuple[str, ...] = ()
    inliers: tuple[float, int, float, int] | None = None
    """Robust losses: (cost, dof, RMS) of the poses not listed as outliers, and how many
    were listed; the noise check judges those, as the loss did."""
    n_prior: int = 0
    """Prior pseudo-observations among the rows (their cost is in `cost_final`)."""
    bounds: tuple[str, ...] | None = None
    """Estimated parameters on one of their bounds (None when no bounds were given)."""
    bound_gain: float = 0.0
    """Cost decrease freeing those from their bounds would add to the free ones'."""
    lack_of_fit: object = None
    """The `casecal.identification.lack_of_fit.LackOfFit` of smooth joint errors beside
    the estimates: without σ, whether the residuals are noise; with σ, only when they
    exceed it, whether that is a model error (None: not judged)."""
    rms_before: float | None = None
    """RMS error (m) of the nominal robot with its frames fitted, the uncalibrated error
    (`casecal.identification.reference`); None: `rms_start`."""

    @property
    def uncalibrated(self) -> float:
        """The uncalibrated RMS error, m."""
        return self.rms_start if self.rms_before is None else self.rms_before


def audit(f: Facts) -> Audit:
    """Run the checks of the module doc on `f`."""
    return Audit(
        (
            _converged(f),
            _no_growth(f),
            _noise(f),
            _prediction(f),
            _held(f),
            _outside(f),
            *([_bounds(f)] if f.bounds is not None else []),
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
    # beyond the noise, the estimates' standard errors are the residuals', not σ's: one
    # of those is what a step must promise (a model error's residual promises a little
    # with every step)
    known = f.known and not beyond_noise(f)
    scale = 1.0 if known else (2.0 * f.cost_final / f.dof if f.dof > 0 else 1.0)
    limit = OPTIMALITY * scale + f.floor
    unit = "noise variances" if known else "residual variances"
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
    if not ok and not f.known and f.rms_final <= NEGLIGIBLE_RMS:
        ok, text = (
            True,
            (
                f"RMS residual {f.rms_final * 1e3:.2g} mm, below anything measurable "
                f"({NEGLIGIBLE_RMS * 1e3:g} mm)"
            ),
        )
    if not ok:
        text += (
            ": the fit stopped before the minimum (a nearly flat valley: more iterations "
            "with --max-iterations, or more, better-spread poses"
            + (
                "; or bounds the data push against, which IPOPT approaches slowly: widen them)"
                if f.bounds is not None
                else ")"
            )
        )
    return Check("converged", ok, text)


def _no_growth(f: Facts) -> Check:
    ok = f.cost_final <= f.cost_start * (1 + 1e-9) + f.floor
    text = f"RMS {f.rms_start * 1e3:.4g} mm at the start, {f.rms_final * 1e3:.4g} mm after"
    if ok and f.rms_final > 1.01 * f.rms_start + 1e-9:
        # the cost weighs measured orientations too: it can fall while positions get worse
        text += (
            f"; the positions' RMS grew, while the cost, which weighs the measured "
            f"orientations too, fell from {f.cost_start:.4g} to {f.cost_final:.4g}"
        )
    if not ok:
        text += (
            ": the fit made the residuals larger (a one-shot linearisation far from the "
            "truth; use an iterated method)"
        )
    return Check("residual did not grow", ok, text)


SMALL_CHI2 = 0.25
"""A reduced χ² below this (residuals under half the stated σ) passes the noise check's
loose lower bound but is said in words: the standard errors scale with the σ."""


def _noise(f: Facts) -> Check:
    name = "residual consistent with the noise"
    if f.dof <= 0:
        return Check(
            name,
            False,
            f"{f.dof + f.n_estimated} measured coordinates for {f.n_estimated} estimates "
            "leave no residual degrees of freedom: any values fit these data exactly, and "
            "nothing checks them (measure more poses)",
        )
    cost, dof, rms, excluded = f.inliers or (f.cost_final, f.dof, f.rms_final, 0)
    without = f" without the {excluded} outlying poses" if excluded else ""
    at_floor = f.cost_final <= f.floor or (f.one_shot and f.rms_final <= RESOLUTION)
    if f.known:
        chi2 = 2.0 * cost / dof
        bound = SIGMA_SLACK**2 * chi2_quantile(CHI2_LEVEL, dof) / dof
        low = chi2_quantile(1.0 - CHI2_LEVEL, dof) / dof / SIGMA_HIGH**2
        ok = low <= chi2 <= bound or (chi2 < low and at_floor)
        text = (
            f"reduced χ²{without} = {chi2:.3g} (bounds {low:.3g} to {bound:.3g}; residuals "
            f"{np.sqrt(chi2):.3g}× σ)"
        )
        if chi2 > bound:
            text += (
                ": the model does not fit these data to their noise (a parameter missing "
                "from the set, a wrong frame, outliers, a prior the data contradict, or a σ "
                "that is too small)"
            )
        elif not ok:
            text += (
                f": the residuals are {1 / np.sqrt(chi2):.3g} times smaller than the stated "
                "σ, more than chance allows: σ is too large (millimetres given as metres?), "
                "and parameters held as below the noise may matter; state the instrument's σ"
            )
        elif chi2 < SMALL_CHI2:  # within the loose bound, still worth a word
            text += (
                f": the residuals are {1 / np.sqrt(chi2):.3g} times smaller than the stated "
                "σ; if that is not the instrument's own, the standard errors are as many "
                "times too large"
            )
    else:
        ok = rms <= PLAUSIBLE_NOISE
        text = f"no σ stated; RMS residual{without} {rms * 1e3:.4g} mm"
        if not ok:
            text += (
                f", more than any position instrument's noise ({PLAUSIBLE_NOISE * 1e3:g} mm): "
                "the model does not fit; if your instrument really is that noisy, state its "
                "σ (--noise, or a sigma_mm column) and the fit is judged against it"
            )
    model_error = False
    if f.lack_of_fit is not None and not at_floor and (not f.known or not ok):
        lof = f.lack_of_fit
        matter, statistic, limit = held_matter(lof.gain, lof.n_extra, lof.cost, lof.dof, False)
        text += (
            f"; smooth functions of the joint values explain {statistic:.3g}× more per "
            f"direction than what remains (chance: up to {limit:.3g})"
        )
        if matter and f.known:
            # σ is the instrument's: what exceeds it and follows the joint values is the
            # model's, and it limits the calibration, not the noise
            model_error = True
            text += (
                f": a MODEL ERROR, not noise: the residuals (RMS {f.rms_final * 1e3:.3g} mm "
                "per point) follow the joint values, a pose-dependent effect the rigid "
                "model lacks (joints bending under gravity, i.e. elasticity; joint-angle "
                "harmonics; a parameter not asked for); expect a held-out error about the "
                "residuals', not the noise's (add the term, e.g. with_compliance)"
            )
        elif matter:
            ok = False
            text += (
                ": the residuals follow the joint values, a model error (a term the model "
                "lacks: gravity compliance, joint-angle harmonics, a parameter not asked "
                "for), not noise; its held-out error will exceed the prediction (add the "
                "term, e.g. with_compliance, or state the instrument's σ)"
            )
    if f.smoothness is not None and not at_floor:
        smooth = f.smoothness < SMOOTH
        text += f"; neighbouring {f.items}' residuals differ {f.smoothness:.2f}× as much as noise's"
        if smooth:
            ok = False
            text += (
                " would: the residuals change smoothly with the joint values, a model error "
                "(a parameter missing or held, a fit stuck short of the minimum), not noise"
            )
    return Check(name, ok, text, cause=model_error)


def beyond_noise(f: Facts) -> bool:
    """With σ stated, whether the residuals exceed it by more than chance (the noise
    check's χ² bound): a model error or a stalled fit, against which a held parameter's
    or a stalled step's gain is judged in residual variances, not σ's."""
    if not f.known or f.dof <= 0:
        return False
    cost, dof, _, _ = f.inliers or (f.cost_final, f.dof, f.rms_final, 0)
    return 2.0 * cost / dof > SIGMA_SLACK**2 * chi2_quantile(CHI2_LEVEL, dof) / dof


def smoothness(q: np.ndarray, residuals: np.ndarray, seed: int = 0) -> float | None:
    """How much the residuals of neighbouring poses differ, relative to independent noise.

    For each pose, the nearest other pose in joint space (joints scaled to the range they
    span in the data); the mean squared difference of their residual vectors over twice
    the mean squared residual. About 1 for noise, which is independent from pose to pose;
    near 0 for a model error, which changes smoothly with the joint values. Exact repeats
    of a pose are not neighbours (a file's duplicated rows would read as smooth). None for
    fewer than 12 poses with a distinct neighbour. At most `SMOOTHNESS_POSES` poses (a
    fixed random subset) are compared.

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
    from scipy.spatial import cKDTree  # scipy loads slowly; only fits with data need it

    span = np.ptp(q, axis=0)
    z = (q - q.min(axis=0)) / np.where(span > 0, span, 1.0)
    # itself, and repeated rows of a file, are at distance 0: a copy is no neighbour, so
    # the nearest is the first at a positive distance among the 8 closest (asked for only
    # where the closest other is a copy: 2 per pose cost half as much as 8)
    tree = cKDTree(z)
    d, index = tree.query(z, k=min(n, 2))
    nearest, has = index[:, -1], d[:, -1] > 0
    copies = np.flatnonzero(~has)
    if copies.size:  # n >= 12 here
        d, index = tree.query(z[copies], k=min(n, 8))
        first = np.argmax(d > 0, axis=1)
        rows = np.arange(copies.size)
        nearest[copies], has[copies] = index[rows, first], d[rows, first] > 0
    total = 2.0 * np.mean(np.sum(r[has] ** 2, axis=1)) if has.sum() >= 12 else 0.0
    if total == 0:
        return None
    return float(np.mean(np.sum((r[has] - r[nearest[has]]) ** 2, axis=1)) / total)


def _held(f: Facts) -> Check:
    name = "held parameters do not matter"
    if not f.held:
        return Check(name, None, "none held for the noise")
    # beyond the noise, judged against the residual: any direction picks up some of a
    # model error, and only gaining more than the rest of it says a held one matters
    known = f.known and not beyond_noise(f)
    matter, statistic, bound = held_matter(f.held_gain, len(f.held), f.cost_final, f.dof, known)
    ok = not matter or f.cost_final <= f.floor
    if known:
        text = (
            f"freeing {listed(f.held)} would lower the cost by {statistic / 2:.3g} noise "
            f"variances (chance: up to {bound / 2:.3g})"
        )
    else:
        text = (
            f"freeing {listed(f.held)} would explain {statistic:.3g}× more per parameter "
            f"than what remains (chance: up to {bound:.3g})"
        )
    if not ok:
        text += (
            ": the data do see them; the residuals are a missing parameter, not noise ("
            + ("" if known or f.known else "state the measurement σ, or ")
            + "measure more, better-spread poses, so that they are determined)"
        )
    return Check(name, ok, text)


def _outside(f: Facts) -> Check:
    name = "parameters not asked for do not matter"
    if not f.outside_visible:
        return Check(name, None, "none outside the asked-for set moves the measured points")
    known = f.known and not beyond_noise(f)  # as for the held ones
    matter, statistic, bound = held_matter(
        f.outside_gain, f.outside_visible, f.cost_final, f.dof, known
    )
    ok = not matter or f.cost_final <= f.floor
    lead = ", ".join(f.outside_leading)
    which = f" (most: {lead})" if not ok else ""
    if known:
        text = (
            f"freeing the {f.outside_visible} directions they add{which} would lower the "
            f"cost by {statistic / 2:.3g} noise variances (chance: up to {bound / 2:.3g})"
        )
    else:
        text = (
            f"freeing the {f.outside_visible} directions they add{which} would explain "
            f"{statistic:.3g}× more per direction than what remains (chance: up to "
            f"{bound:.3g})"
        )
    if not ok:
        text += (
            ": the data see deviations of parameters that were not asked for, and the "
            f"estimates absorbed them (add {lead} to --parameters, or ask for all)"
        )
    return Check(name, ok, text)


def _bounds(f: Facts) -> Check:
    name = "no bound decides an estimate"
    if not f.bounds:
        return Check(name, True, "no estimate sits on its bounds")
    matter, statistic, bound = held_matter(
        f.bound_gain, len(f.bounds), f.cost_final, f.dof, f.known
    )
    unit = "noise variances" if f.known else "per parameter, in residual variances"
    gain = statistic / 2 if f.known else statistic
    one = len(f.bounds) == 1
    text = (
        f"{listed(f.bounds)} {'sits on its' if one else 'sit on their'} bounds; freeing "
        f"{'it' if one else 'them'} would lower the cost by {gain:.3g} {unit} (chance: up "
        f"to {bound / 2 if f.known else bound:.3g})"
    )
    ok = not matter or f.cost_final <= f.floor
    if not ok:
        text += (
            ": the data want them beyond, so the bounds, not the data, set them, and the "
            "other estimates absorbed the rest (widen the bounds, or look for what else "
            "is wrong: the model, the nominal values, the frame)"
        )
    return Check(name, ok, text)


def _prediction(f: Facts) -> Check:
    name = "prediction no worse than uncalibrated"
    if f.unsupported:
        return Check(
            name,
            False,
            f"these poses cannot determine {listed(f.unsupported)} (their uncertainty "
            f"would exceed the uncalibrated error of {f.uncalibrated * 1e3:.3g} mm on poses "
            "across the workspace); held at nominal, but what the other estimates absorbed "
            "of them holds only on poses like the measured ones (measure more, "
            "better-spread poses, or ask for fewer parameters)",
        )
    if f.blind_here:
        still = f" ({', '.join(f.still)} in every pose)" if f.still else ""
        return Check(
            name,
            False,
            f"these poses cannot tell {listed(f.blind_here)} from the estimated "
            f"parameters{still}, but poses across the joint ranges would: the estimates "
            "absorb their deviations, and the calibrated robot is right only on poses like "
            "the measured ones (measure poses that move every joint, each independently of "
            "the others; or, if the robot will only work at poses like these, leave these "
            "parameters out of --parameters)",
        )
    if f.predicted_rms is None:
        return Check(name, None, f.prediction_note or "no joint limits to draw poses from")
    p, c = f.predicted_rms, f.correction_rms
    # the correction c is the true error before calibration b plus the estimate's own
    # error (mean square p²): c² = b² + p² + 2⟨b, error⟩, and the cross term of one fit
    # can reach ±2 b p (Cauchy-Schwarz; it does when the estimates absorb something the
    # poses cannot tell apart). So b² is about c² − p², and at least c² − p² − 2 c p: the
    # prediction must beat that least value, or the data cannot show the fit helps
    before = np.sqrt(max(c**2 - p**2, 0.0))
    least = np.sqrt(max(c**2 - p**2 - 2.0 * c * p, 0.0))
    ok = p <= max(least, f.noise_rms, 1e-9)
    text = (
        f"predicted RMS error on {PREDICTION_POSES} new poses within the joint limits "
        f"{p * 1e3:.3g} mm (from the covariance), against about {before * 1e3:.3g} mm before "
        "calibration"
        if c > p
        else f"predicted RMS error on {PREDICTION_POSES} new poses within the joint limits "
        f"{p * 1e3:.3g} mm (from the covariance), more than the {c * 1e3:.3g} mm RMS the "
        "calibration moves them by"
    )
    if not ok:
        # the least the robot was off by, once the fit's own error is allowed for
        least_text = (
            f"at least {least * 1e3:.3g} mm" if least > 0 else "possibly no more than predicted"
        )
        text += (f" ({least_text}, allowing for the fit's own error)" if c > p else "") + (
            ": these poses do not support the estimated parameters, and the calibrated "
            "robot may be no better than the nominal one away from them (measure more, "
            "better-spread poses, or ask for fewer parameters)"
        )
    elif p > max(least, 1e-9):  # passed on the noise: the data cannot tell better
        text += (
            f"; within the measurement noise ({f.noise_rms * 1e3:.3g} mm RMS per coordinate), "
            "as near as these data can tell"
        )
    return Check(name, ok, text)


def predicted_rms(
    robot: Robot, start: Robot, estimated, cov: np.ndarray, seed: int = 0
) -> tuple[float, float] | None:
    """The error the covariance predicts, and the correction the fit made, across the
    workspace: RMS over `PREDICTION_POSES` uniform poses, m.

    The error of each measured point is Gaussian with covariance ``J C Jᵀ``; its mean
    square is ``trace(J C Jᵀ)``. The correction is how far the measured points of
    `robot` lie from those of `start` (the nominal robot with its frames fitted, so that
    frames nobody knew before measuring do not count as a correction). None when the
    robot has no limits to draw poses from.
    """
    try:
        q = uniform(robot, PREDICTION_POSES, seed=seed)
    except CalibrationError:
        return None
    moved = robot.measured_points(q) - start.measured_points(q)
    correction = float(np.sqrt(np.mean(np.sum(moved.reshape(-1, 3) ** 2, axis=1))))
    if not estimated:
        return 0.0, correction
    chain = kinematics.chain(robot.structure)
    p = robot.vector()  # anchored: columns in the deviations, those `cov` is of
    J = chain.evaluate("points_jacobian", q, p, chain.columns(list(estimated)), anchor=p)
    J = J * moves_robot(robot, estimated)  # a camera rig's poses and lens: not the robot's
    mean_square = np.einsum("nik,kl,nil->", J, cov, J) / (J.shape[0] * J.shape[1] / 3)
    return float(np.sqrt(max(mean_square, 0.0))), correction
