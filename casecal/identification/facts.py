"""Gather what the answer audit looks at from where the rounds of a fit ended.

Every number the audit judges is measured here, on the problem the solver solved: with a
robust loss, the poses it left out are left out; with a prior, its pseudo-observations
are rows of the problem (the minimum of data plus prior is not the data's minimum); with
bounds, what freeing the active ones would gain is told apart from what the free
parameters could still gain.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.parameters import unit
from .audit import SIGMA_SLACK, Facts, predicted_rms, smoothness
from .evidence import blind_only_here, gauge_bound, outside_gain, still_joints
from .lack_of_fit import lack_of_fit
from .linalg import Reduction
from .outliers import outlier_poses
from .problem import Problem
from .rank import held_gain
from .rounds import Outcome, measured_weights
from .solvers import ROUNDING, floor_cost
from .uncertainty import uncertainty


@dataclass(frozen=True)
class Gathered:
    """`Facts` and what `casecal.identify` builds its result from.

    Attributes
    ----------
    facts : Facts
    covariance : ndarray, shape (k, k)
        Of the estimated deviations, fit frame.
    estimated : Problem
        At the fitted robot, the estimated parameters only (weighted as in the fit).
    at_end : Problem
        At the fitted robot, every asked-for parameter.
    outliers : tuple of int
        Poses whose residuals stand out.
    """

    facts: Facts
    covariance: np.ndarray
    estimated: Problem
    at_end: Problem
    outliers: tuple[int, ...]


def gather(
    make,
    robot,
    start,
    reference,
    names,
    out: Outcome,
    settings,
    e0: float,
    e_before: float,
    gauge=(),
    at_size: bool = False,
) -> Gathered:
    """Measure the `Facts` of a fit (module doc).

    Parameters
    ----------
    make : callable(robot, names=...) -> Problem
        The measurements, fit frame.
    robot, start : Robot
        The nominal robot (for the parameters not asked for) and where the fit started.
    reference : Robot
        The nominal robot with the asked-for frames fitted
        (`casecal.identification.reference`): the robot before calibration.
    names : list of str
        The asked-for parameters.
    out : Outcome
        Where the rounds ended.
    settings : casecal.identification.rounds.Settings
    e0, e_before : float
        RMS error at the start and of `reference`, m.
    gauge : sequence of str
        Frame parameters of the robot's base not asked for because the data cannot see
        them (a contact session's, the first session's): free across the joint ranges
        too (`casecal.identification.evidence.blind_only_here`).
    at_size : bool
        Contact sessions only: what freeing parameters would gain is judged at the
        robot's size, which contacts cannot see: held parameters by
        `Reduction.decrease_at_size`, those not asked for without the lengths.
    """
    robust = settings.loss != "linear"
    outside = _outside(robot, names)
    # one kernel of the asked-for and the other parameters: one pass over the poses
    # serves the covariance, the held parameters' gain and the outside ones'
    final = make(out.robot, names=names, kernel_names=[*names, *outside])
    at_start = make(start, names=names)
    if robust:
        final, at_start = final.reweighted(out.weights), at_start.reweighted(out.weights)
    est = final.restricted(out.estimated)
    x0 = np.zeros(len(out.estimated))
    linear = est.reduced(x0)
    prior_w = np.array([1.0 / settings.prior.get(n, np.inf) for n in out.estimated])
    cov, _ = uncertainty(linear, None, settings.known, names, out.estimated, prior_w)
    moved = out.robot.deviations_from(start, out.estimated)  # rotations: not differences
    deviation = np.array([moved[n] for n in out.estimated])
    fit = _with_prior(linear, prior_w, deviation)
    r_start = at_start.residual(np.zeros(len(names)))
    active = _active(out.estimated, deviation, settings.bounds)
    free = [i for i, n in enumerate(out.estimated) if n not in active]
    decrease = fit.columns(free).solve()[1] if free else 0.0
    point_residuals = est.point_residuals(x0)
    q = est.q
    # least squares: judged against the fit without them, which their pull does not drag
    outliers = outlier_poses(
        make(out.robot, names=out.estimated), settings.w, settings.known, refit=not robust
    )
    inliers = _inliers(make(out.robot, names=out.estimated), outliers) if robust else None
    # contacts alone: the lengths not asked for are the robot's size (module doc of
    # casecal.identification.contact); freeing them all would free the size, which
    # explains any residual of contacts, so the test frees the others
    tested = [n for n in outside if unit(n) != "m"] if at_size else outside
    unasked = outside_gain(final.restricted([*out.estimated, *tested]), out.estimated)
    keep = np.setdiff1d(np.arange(len(q)), outliers) if robust else slice(None)
    n_prior = int(np.sum(prior_w > 0))
    workspace = predicted_rms(out.robot, reference, out.estimated, cov)
    # the one-shot method's leftovers are its linearisation's, which "converged" judges
    # with σ, only to say what residuals beyond the noise are (the audit's model error):
    # χ² within SIGMA_SLACK² passes the noise check whatever this says
    chi2 = fit.rr / max(linear.rows - len(out.estimated), 1)
    smooth = (
        None
        if (settings.known and chi2 <= SIGMA_SLACK**2) or settings.method == "svd"
        else lack_of_fit(
            make(out.robot, names=out.estimated),
            robot.joint_types,
            keep if robust else None,  # a robust fit judged on its inliers, unweighted
        )
    )
    # what only moves the whole robot once the contact frame it is seen in is free
    gauge_free = gauge_bound(final, out.robot, out.estimated, gauge, out.unsupported)
    facts = Facts(
        solver_status=out.solver_status,
        solver_message=out.message,
        cost_start=0.5 * float(r_start @ r_start),
        cost_final=0.5 * fit.rr,
        floor=floor_cost(est, ROUNDING),
        predicted_decrease=decrease,
        known=settings.known,
        dof=(inliers[1] if inliers else linear.rows - len(out.estimated)) + n_prior,
        rms_start=e0,
        rms_before=e_before,
        rms_final=point_rms(point_residuals, est._unmeasured),
        settled=out.settled,
        rounds=out.rounds,
        predicted_rms=None if workspace is None else workspace[0],
        correction_rms=0.0 if workspace is None else workspace[1],
        noise_rms=float(np.sqrt(np.mean(1.0 / measured_weights(settings.w) ** 2)))
        if settings.known
        else point_rms(point_residuals, est._unmeasured) / np.sqrt(3.0),
        n_points=point_residuals.size // 3
        if est._unmeasured is None
        else np.count_nonzero(~est._unmeasured) / 3,
        n_estimated=len(out.estimated),
        one_shot=settings.method == "svd",
        unsupported=tuple(n for n in out.unsupported if n not in gauge_free),
        held=tuple(out.pruned),
        smoothness=smoothness(q[keep], point_residuals[keep]),
        held_gain=held_gain(
            final.reduced(np.zeros(len(names))),
            names,
            out.estimated,
            out.pruned,
            at_size=at_size,
        )
        if out.pruned
        else 0.0,
        # the one-shot method chose its set where it linearised
        blind_here=blind_only_here(
            final,
            out.start_robot if settings.method == "svd" else out.robot,
            out.estimated,
            out.pruned,
            free=tuple(gauge),
        ),
        still=still_joints(q, robot),
        outside_gain=unasked.gain,
        outside_visible=unasked.n_visible,
        outside_leading=unasked.leading,
        inliers=inliers,
        n_prior=n_prior,
        bounds=None if not settings.bounds else tuple(active),
        bound_gain=fit.solve()[1] - decrease if active else 0.0,
        lack_of_fit=smooth,
    )
    return Gathered(facts, cov, est, final, outliers)


def _outside(robot, names) -> list[str]:
    return [n for n in robot.parameter_names if n not in names]


def _with_prior(linear: Reduction, prior_w, deviation) -> Reduction:
    """The prior's pseudo-observations ``0 = deviation ± σ_p`` as rows of ``[J | r]``."""
    rows = prior_w > 0
    if not np.any(rows):
        return linear
    return linear.fold(np.diag(prior_w)[rows], -(prior_w * deviation)[rows])


BOUND_TOLERANCE = 1e-6
"""A deviation within this fraction of its bounds' width of a bound sits on it."""


def _active(estimated, deviation, bounds) -> list[str]:
    """Estimated parameters that sit on one of their bounds."""
    active = []
    for name, value in zip(estimated, deviation, strict=True):
        if name in bounds:
            lo, hi = bounds[name]
            tol = BOUND_TOLERANCE * (hi - lo)
            if value <= lo + tol or value >= hi - tol:
                active.append(name)
    return active


def _inliers(problem: Problem, outliers) -> tuple[float, int, float, int]:
    """(cost, dof, RMS in m, outliers) of the poses not in `outliers`, unweighted by the
    loss: what a robust fit's residuals say about the noise."""
    x0 = np.zeros(len(problem.names))
    keep = np.setdiff1d(np.arange(len(problem.q)), outliers)
    r = problem.residual(x0).reshape(len(problem.q), -1)[keep].ravel()
    unmeasured = None if problem._unmeasured is None else problem._unmeasured[keep]
    rms = point_rms(problem.point_residuals(x0)[keep], unmeasured)
    rows = np.count_nonzero(problem.w_rows[keep])  # coordinates not measured: no rows
    return 0.5 * float(r @ r), rows - len(x0), rms, len(outliers)


def point_rms(point_residuals: np.ndarray, unmeasured: np.ndarray | None = None) -> float:
    """RMS length of point residuals (..., 3), m.

    With coordinates not measured (`unmeasured`, True where σ is inf; their residuals
    0), √3 times the RMS of the measured coordinates: the length a point's error would
    have if every coordinate were measured alike.
    """
    if unmeasured is not None:
        n = np.count_nonzero(~np.asarray(unmeasured))
        return float(np.sqrt(3.0 * np.sum(np.square(point_residuals)) / max(n, 1)))
    return float(np.sqrt(np.mean(np.sum(np.reshape(point_residuals, (-1, 3)) ** 2, axis=1))))
