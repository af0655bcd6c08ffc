"""Identification of parameter deviations from measured positions: `identify`.

Every method solves the same weighted least-squares problem in the deviations ``x`` of the
estimated parameters::

    minimise  0.5 Σ_i Σ_rows (r_i,row(p0 + x) / σ_i,row)²

whose rows per pose are the measured points' coordinates, ``y - f(q, p)`` (m), and, when
orientations were measured, the rotation vector ``log(R_meas R(q, p)ᵀ)`` (rad). Columns
of the Jacobian are scaled to unit norm before any factorisation, so metres and radians
do not decide the rank. The pieces, in order:

- `casecal.identification.start`: the frame the fit works in (a rigid fit brings a far,
  turned instrument's points near the robot) and where it starts;
- `casecal.identification.rounds`: the fit in rounds, estimating a base set of what the
  data can see where the fit ends, holding the rest at nominal, and holding what the noise
  does not determine;
- `casecal.identification.audit`: the checks that decide ``success``;
- `casecal.identification.calibration`: the result, in the instrument's frame.
"""

from __future__ import annotations

import logging
import time
from functools import partial
from numbers import Real

import numpy as np

from .._threads import with_one_blas_thread
from ..data.measurements import Measurements, broadcast_sigma
from ..errors import CalibrationError
from ..model.parameters import select
from ..model.robot import Robot
from ..observations.pixels import PixelMeasurements
from .analysis import represent, selection
from .audit import audit
from .calibration import Calibration
from .camera_fit import identify_camera
from .contact import check_robot as check_contact_robot
from .contact import contact_checks, plausible_error
from .distances import DistanceMeasurements, identify_distances
from .facts import gather
from .fitting import check_iterations, outcome_fields, rms_of, shared_problems, verdict
from .problem import Problem
from .reference import FALLBACK_NOTE, frame_parameters, frames_fitted
from .rounds import LOSSES, Settings, fit_in_rounds
from .scale import door, with_size_check
from .sessions import contact_held, session_robot, with_indicators
from .sessions import door as session_door
from .sessions import fitted as fitted_sessions
from .sessions import resolve as resolve_sessions
from .sessions import start as session_start
from .solvers import SOLVERS
from .start import FitFrame, choose_frame, partial_base_start
from .summary import outliers_lead, stand_out

log = logging.getLogger(__name__)

METHODS = tuple(SOLVERS)
DEFAULT_METHOD = "gauss-newton"
"""Iterated: it reaches the least-squares solution wherever the one-shot step does not."""


@with_one_blas_thread
def identify(
    robot: Robot,
    measurements: Measurements,
    parameters=None,
    method: str = DEFAULT_METHOD,
    *,
    noise=None,
    bounds: dict | None = None,
    prior: dict | None = None,
    max_iterations: int = 100,
    tolerance: float = 1e-10,
    truth: dict | None = None,
    orientation_sigma: float | None = None,
    loss: str = "linear",
    loss_scale: float = 3.0,
    progress=None,
    per_session=None,
) -> Calibration:
    """Identify the parameter deviations of `robot` from measured positions.

    Parameters
    ----------
    robot : Robot
        The nominal robot.
    measurements : Measurements, DistanceMeasurements or PixelMeasurements
        Joint values and measured tool-point positions (m), with noise σ; or distances
        between pairs of poses (`casecal.identification.distances.identify_distances`);
        or a camera's pixels of a checkerboard
        (`casecal.identification.camera_fit.identify_camera`). All run the same rounds,
        rank, audit and covariance; the options a kind does not take are refused.
    parameters : str, list of str or None
        What to identify: names, families or ``"all"``. Default: the paper's set θ, a, d
        of every joint (α fixed).
    method : {"svd", "gauss-newton", "lm", "ipopt"}
        ``"svd"``: the paper's procedure, one linearisation at the nominal parameters and
        the SVD pseudo-inverse with Numerical Recipes' cut-off (`nr_threshold`).
        ``"gauss-newton"``: that step repeated at the current estimate (halved while it
        does not lower the cost) until the step or the cost change falls under the
        tolerance. ``"lm"``: Levenberg-Marquardt with Nielsen's damping update.
        ``"ipopt"``: the same least squares as a CasADi NLP solved by IPOPT with a
        Gauss-Newton Hessian; accepts `bounds` and `prior`.
    noise : float, array-like or None
        Measurement σ in m (scalar, per axis (3,), or per coordinate (N, 3)) to weight the
        residuals with; default: the σ stored in `measurements`. With σ = 0 the residuals
        are unweighted and standard errors use the residual scale.
    bounds : dict of str to (float, float), optional
        ``"ipopt"`` only: lower and upper bound on the deviation of named parameters, SI
        (not the base frame's, which is fitted from a rigid fit of the data).
    prior : dict of str to float, optional
        ``"ipopt"`` only: standard deviation (SI) of a Gaussian prior centred on the nominal
        value, per named parameter (regularisation toward nominal; not the base frame's).
        Needs a measurement σ.
    max_iterations : int
        Iteration limit of the iterated methods. Default 100.
    tolerance : float
        Relative step tolerance of the iterated methods. Default 1e-10.
    truth : dict, optional
        True deviations (SI), for simulations: the result's table then shows errors.
    orientation_sigma : float, optional
        σ of measured orientations, rad (default: the measurements'; without one, 1 mrad
        of rotation weighs like 0.1 mm of position).
    loss : {"linear", "huber", "soft_l1"}
        ``"linear"`` is least squares. The robust losses down-weight measured points whose
        residual norm e exceeds `loss_scale` (Huber: weight c/e beyond c; soft-L1:
        1/√(1 + (e/c)²)), by iteratively reweighted least squares around `method`; the
        poses that then stand out (`Calibration.outliers`) are left out and the rest
        fitted by least squares, so that standard errors and the audit's noise check hold
        (a bounded influence is still a bias).
    loss_scale : float
        c: in units of the measurement σ when σ is given (default 3 σ), otherwise in units
        of the residuals' robust standard deviation (from their median).
    progress : callable(str), optional
        Called with one line per solver iteration ("round 1, iteration 3: RMS 0.021 mm"),
        for showing the progress of long fits.
    per_session : ("base",) or ("base", "tool"), optional
        With measurements of two or more sessions (`Measurements.session`): which frames
        each session has of its own. The robot's parameters are shared; every session's
        base frame is estimated whatever `parameters` asks for (the first session's is
        ``base_x`` …, the calibrated robot's; the others' ``base_x@LABEL`` …; a
        ``base*`` in `parameters` names them all), and with ``"tool"`` its tool frame
        too (``tool_x@LABEL`` …; for a probe re-mounted between sessions). Default: the
        base only (or the frames `robot` has per session, for a `Calibration`'s
        nominal). See `casecal.identification.sessions`.

    Returns
    -------
    Calibration
        With sessions, `Calibration.sessions` gives each session's fitted frames, and
        `Calibration.robot` is the calibrated robot with the first session's.

    Raises
    ------
    CalibrationError
        Unknown method or parameter, measurements of another robot, fewer measured
        coordinates than parameters to estimate, bounds or prior for a method without them.
    """
    t_start = time.perf_counter()
    loss_scale = _check_options(method, bounds, prior, loss, loss_scale)
    max_iterations, tolerance = check_iterations(max_iterations, tolerance)
    bounds, prior = _check_bounds(bounds or {}), _check_prior(prior or {})
    if not isinstance(robot, Robot):
        raise CalibrationError(
            f"identify takes a Robot, got {type(robot).__name__}; load one first, e.g. "
            "cc.load_robot('puma560') or cc.load_robot('robot.urdf')"
        )
    given = {"noise": noise, "bounds": bounds or None, "prior": prior or None}
    given |= {"orientation_sigma": orientation_sigma, "per_session": per_session}
    if isinstance(measurements, DistanceMeasurements):
        _refuse(given, loss, "distance", "their own (DistanceMeasurements.sigma)")
        return identify_distances(
            robot, measurements, parameters, method, max_iterations, tolerance, truth, progress
        )
    if isinstance(measurements, PixelMeasurements):
        _refuse(given, loss, "camera", "the measurements' sigma_px")
        if robot.coupling is not None:
            raise CalibrationError(
                "camera calibration of a robot with coupled joints is not supported yet; "
                "calibrate robot.uncoupled() with the model's joint values "
                "(robot.model_joints(q)) instead"
            )
        options = {"max_iterations": max_iterations, "tolerance": tolerance, "truth": truth}
        return identify_camera(
            robot, measurements, parameters, method, progress=progress, **options
        )
    if measurements.contact:
        if robot.coupling is not None:
            raise CalibrationError(
                "contact sessions (a fixed point, a plane) are not supported for a robot "
                "with coupled joints yet"
            )
        check_contact_robot(robot, measurements)
    if robot.coupling is not None:
        return _coupled(
            robot,
            measurements,
            parameters,
            method,
            noise=noise,
            bounds=bounds or None,
            prior=prior or None,
            max_iterations=max_iterations,
            tolerance=tolerance,
            truth=truth,
            orientation_sigma=orientation_sigma,
            loss=loss,
            loss_scale=loss_scale,
            progress=progress,
            per_session=per_session,
        )
    sessions = resolve_sessions(robot, measurements, per_session)
    held = []
    robot = session_robot(robot, sessions)  # a frame per session; itself for one session
    names = _selection(robot, parameters, sessions)
    if measurements.q.shape[1] not in (robot.dof, robot.n_inputs):
        extra = f" and {len(robot.inputs)} inputs" if robot.inputs else ""
        raise CalibrationError(
            f"measurements have {measurements.q.shape[1]} joint values per pose but robot "
            f"{robot.name!r} has {robot.dof} joints{extra}; use the robot the data came from"
        )
    if robot.is_tree:
        if measurements.orientations is not None:
            from ..model.kinematics import tree_refusal

            raise tree_refusal("orientation measurements")
        _with_points(robot, measurements.n_points)  # one point per tip, before the door
    if sessions is None:
        door(robot, measurements)  # unit slips, before any fit
    else:  # each session in its own instrument frame
        session_door(robot, measurements, sessions, door)
    q, y = measurements.q, measurements.points  # y: (N, m, 3)
    if sessions is not None:
        q = with_indicators(robot, q, sessions)
    robot, point_note = _with_points(robot, measurements.n_points)
    names = _selection(robot, parameters, sessions) if point_note else names
    unknown = [n for n in {**bounds, **prior} if n not in names]
    if unknown:
        raise CalibrationError(
            f"bounds/prior name {unknown[0]!r} is not among the asked-for parameters"
        )
    on_base = [n for n in {**bounds, **prior} if n.startswith("base_")]
    if on_base:
        # the base is fitted from where a rigid fit of the data puts it, not from nominal:
        # a bound there would bind another quantity than the one the user named
        raise CalibrationError(
            f"bounds and priors on the base frame ({', '.join(on_base)}) are not supported: "
            "the base is where the instrument stands, fitted from a rigid fit of the data; "
            "bound or weigh the joint, tool and point parameters only"
        )
    sigma = measurements.sigma if noise is None else broadcast_sigma(noise, q.shape[0])
    measured = ~np.isinf(measurements.sigma) & ~np.isinf(sigma)  # σ inf: not measured
    if not np.all(measured):
        sigma = np.where(measured, sigma, np.inf)  # a plane's x, y stay not measured
    known = bool(np.all(sigma[measured] > 0))
    if not known and np.any(sigma[measured] > 0):
        raise CalibrationError(
            "noise sigma is zero for some coordinates and not others; give every coordinate "
            "its sigma (> 0), or none (0 everywhere) to weigh all alike"
        )
    if prior and not known:
        raise CalibrationError(
            "a prior needs the measurement sigma to weigh against; give noise=... (m) or "
            "measurements with sigma"
        )
    w = 1.0 / sigma if known else np.ones_like(sigma)
    if not np.all(measured):  # weight 0, and no position (stored 0) reaches a residual
        w = np.where(measured, w, 0.0)
        y = np.where(measured[:, None, :], y, 0.0)
    w_rot = _orientation_weight(measurements, orientation_sigma, known, w)

    if sessions is None:
        frame, frame_note = choose_frame(robot, q, y, sigma, names, np.mean(w**2, axis=1))
    else:  # one instrument frame per session: each base starts from its own rigid fit
        frame, frame_note = FitFrame.identity(), ""
    make = shared_problems(
        partial(
            Problem,
            q=q,
            y=frame.points_in(y),
            w=w,
            orientations=frame.rotations_in(measurements.orientations),
            w_rot=w_rot,
        )
    )
    start, start_note = robot, frame_note
    if sessions is not None:
        start, start_note = session_start(robot, q, y, w, sessions)
        held = contact_held(start, sessions)  # blind frame parameters: not estimated
        names = [n for n in names if n not in held]
    elif frame.is_identity:
        start, start_note = partial_base_start(robot, lambda r, n: make(r, names=n), names)
    e0 = rms_of(make(start, names=names), len(names))
    settings = Settings(
        method, max_iterations, tolerance, known, w, loss, loss_scale, bounds, prior, progress
    )
    reference = frames_fitted(make, start, names, settings, e0)
    frames = frame_parameters(names, robot)
    if reference is start and frames and len(frames) < len(names):
        start_note = f"{start_note} {FALLBACK_NOTE}".strip()
    e_before = rms_of(make(reference, names=names), len(names))
    if method != "svd" and not bounds and not prior and reference is not start:
        # the fitted base is a start nearer the minimum. Not the tool or the reflectors:
        # moved off the nominal, a tool point on the flange axis would make wrist
        # parameters look visible, and what is fitted of them there stays behind, frozen,
        # when they turn out blind. The one-shot method linearises at nominal as the
        # paper does; bounds and priors are taken from the start values
        start = start.with_parameters(
            {n: reference.parameters[n] for n in names if n.startswith("base_")}
        )
        e0 = rms_of(make(start, names=names), len(names))
    e_rounds = e_before
    if sessions is not None and sessions.kinds:  # contacts hide the robot's error
        e_rounds = max(e_before, plausible_error(start, names))
    out = fit_in_rounds(make, start, names, settings, e_rounds)

    gauge = [n for n in held if "@" not in n]  # the first session's: the robot's base
    # contacts alone see no size: their points are 0, so shrinking the robot explains
    # any residual; the tests of what freeing parameters would gain are at its size
    at_size = sessions is not None and all(sessions.kinds) and bool(sessions.kinds)
    got = gather(make, robot, start, reference, names, out, settings, e0, e_before, gauge, at_size)
    est, x0 = got.estimated, np.zeros(len(out.estimated))
    point_residuals = est.point_residuals(x0)
    checks = with_size_check(audit(got.facts), robot, out.robot, q, y)
    if sessions is not None and sessions.kinds:  # contacts: estimates must stay plausible
        checks = contact_checks(checks, robot, out.robot, out.estimated, at_size)
    status, message = verdict(checks, out.solver_status, out.message)
    # a model error the residuals show explains poses standing out too (where gravity
    # bends the arm most): then they do not lead
    model_error = bool(checks.failures) and checks.failures[0].cause
    lead = status < 0 and outliers_lead(got.outliers, len(q)) and not model_error
    if lead:  # the likelier cause leads (issue 20)
        message = f"{stand_out(got.outliers, loss)}; {message}"

    calibrated = frame.robot_out(out.robot)
    cov = frame.covariance_out(got.covariance, out.estimated, out.robot, robot.base.rpy)
    se = dict.fromkeys(names, float("nan"))
    se.update(zip(out.estimated, np.sqrt(np.diag(cov)).tolist(), strict=True))
    cal = Calibration(
        **outcome_fields(out, got),
        method=method,
        nominal=robot,
        robot=session_robot(calibrated, None),  # the first session's frames
        parameters=tuple(names),
        deviations=calibrated.deviations_from(robot, names),  # rotations: not differences
        standard_errors=se,
        covariance=cov,
        residuals=frame.vectors_out(point_residuals).reshape(-1, 3),
        residuals_before=frame.vectors_out(
            make(reference, names=names).point_residuals(np.zeros(len(names)))
        ).reshape(-1, 3),
        orientation_residuals=frame.vectors_out(est.orientation_residuals(x0)),
        outliers_lead=lead,
        loss=loss
        if loss == "linear"
        else f"{loss} (scale {loss_scale:g}{' sigma' if known else ' robust sd'})",
        status=status,
        message=message,
        sigma_known=known,
        wall_time=time.perf_counter() - t_start,
        start_note=" ".join(t for t in (point_note, start_note, _repeats(q, y)) if t),
        audit=checks,
        representation=_representation(
            calibrated,
            got.at_end,
            frame,
            partial(make, y=y, orientations=measurements.orientations),
            names,
            out,
            se,
        ),
        sessions={}
        if sessions is None
        else fitted_sessions(calibrated, se, point_residuals, sessions, held),
        unmeasured=None if np.all(measured) else np.repeat(~measured, y.shape[1], axis=0),
    )
    return cal.compare_to(truth) if truth is not None else cal


def _refuse(given: dict, loss: str, kind: str, sigma: str) -> None:
    """Refuse the options `given` (not None) that `kind` measurements do not take."""
    unsupported = [k for k, v in given.items() if v is not None]
    unsupported += ["loss"] if loss != "linear" else []
    if unsupported:
        raise CalibrationError(
            f"{kind} measurements do not take {', '.join(unsupported)} yet; their σ is {sigma}"
        )


def _selection(robot: Robot, parameters, sessions) -> list[str]:
    """The asked-for parameters; with sessions, every session's own frames too."""
    names = selection(robot, parameters)
    if sessions is None:
        return names
    return select(robot.parameter_names, [*names, *sessions.names()])


def _coupled(robot: Robot, measurements: Measurements, *args, **options) -> Calibration:
    """`identify` for a robot whose controller joints are coupled (`Robot.coupling`): the
    kernels take the model's joints, so the controller's are mapped once, here, and the
    model alone is fitted (the coupling is no parameter); the result has the coupled
    robots back, and its joint words (`still_joints`) name the controller's joints."""
    import dataclasses

    from .evidence import still_joints

    model = dataclasses.replace(measurements, q=robot.model_joints(measurements.q))
    cal = identify(robot.uncoupled(), model, *args, **options)
    return dataclasses.replace(
        cal,
        nominal=cal.nominal.recoupled(robot),  # with the sessions' frames, if any
        robot=cal.robot.recoupled(robot),
        still_joints=still_joints(measurements.q, robot),
    )


def _representation(calibrated, final, frame, make_world, names, out, se):
    """What each estimate stands for, with the base frame in the instrument's frame."""
    if not frame.is_identity:
        final = make_world(calibrated, names=names)
    if out.end_analysis is out.start_analysis:  # one-shot: what it saw where it linearised
        final = make_world(frame.robot_out(out.start_robot), names=names)
    R = final.reduced(np.zeros(len(names))).R
    return represent(
        R, names, out.estimated, out.pruned, standard_errors=se, sizes=calibrated.sizes
    )


def _check_options(method, bounds, prior, loss, loss_scale) -> float:
    """Check the options beyond `check_iterations`; returns `loss_scale` as a float."""
    if method not in METHODS:
        raise CalibrationError(f"unknown method {method!r}; use one of {', '.join(METHODS)}")
    if (bounds or prior) and method != "ipopt":
        raise CalibrationError("bounds and prior need method='ipopt'")
    if loss not in LOSSES:
        raise CalibrationError(f"unknown loss {loss!r}; use one of {', '.join(LOSSES)}")
    if (
        isinstance(loss_scale, bool)
        or not isinstance(loss_scale, Real)
        or not (np.isfinite(loss_scale) and loss_scale > 0)
    ):
        raise CalibrationError(f"loss_scale must be a positive number, got {loss_scale!r}")
    return float(loss_scale)


def _orientation_weight(measurements: Measurements, orientation_sigma, known, w) -> float:
    """1/σ_rot (1/rad) for measured orientations (default: 1 mrad weighs like 0.1 mm)."""
    if orientation_sigma is None:
        orientation_sigma = measurements.orientation_sigma
    if orientation_sigma is not None:
        try:
            orientation_sigma = float(orientation_sigma)
        except (TypeError, ValueError):
            raise CalibrationError(
                f"orientation_sigma {orientation_sigma!r} is not a number (rad)"
            ) from None
        if not (np.isfinite(orientation_sigma) and orientation_sigma >= 0):
            raise CalibrationError("orientation_sigma must be finite and non-negative (rad)")
        if orientation_sigma > 0 and not known and measurements.orientations is not None:
            # positions would weigh 1 per metre against 1/σ_rot per radian: ignored
            raise CalibrationError(
                "an orientation sigma needs the position sigma too (noise=... or a sigma_mm "
                "column); or give neither, and 1 mrad weighs like 0.1 mm"
            )
    if orientation_sigma:
        return 1.0 / orientation_sigma
    return 0.1 * float(np.mean(w))


def _repeats(q: np.ndarray, y: np.ndarray) -> str:
    """A note when rows repeat earlier ones exactly (a file pasted twice), else ""."""
    # only rows whose first joint value repeats can repeat: those are compared whole
    _, first, count = np.unique(q[:, 0], return_inverse=True, return_counts=True)
    again = count[first] > 1
    rows = np.hstack([q[again], y[again].reshape(int(again.sum()), y[0].size)])
    n = len(rows) - len(np.unique(rows, axis=0))
    if not n:
        return ""
    return (
        f"{n} pose{'s repeat earlier ones' if n > 1 else ' repeats an earlier one'} exactly "
        "(joint values and measured points): each copy counts as a new measurement, so the "
        "standard errors are too small if the rows were copied rather than measured again."
    )


def _with_points(robot: Robot, m: int) -> tuple[Robot, str]:
    """The robot with as many measured points as the data have (new ones at the origin);
    a tree's measured points are its tips."""
    if robot.is_tree:
        if m != len(robot.tips):
            raise CalibrationError(
                f"the measurements have {m} point{'s' if m > 1 else ''} per pose but robot "
                f"{robot.name!r} is a tree with {len(robot.tips)} tips "
                f"({', '.join(robot.tips)}); give one measured point per tip, in that order"
            )
        return robot, ""
    if m == 1 and not robot.points:
        return robot, ""
    if robot.points and len(robot.points) != m:
        raise CalibrationError(
            f"the measurements have {m} points per pose but robot {robot.name!r} has "
            f"{len(robot.points)}; give the robot one point per measured reflector"
        )
    if robot.points:
        return robot, ""
    return robot.with_points(np.zeros((m, 3))), (
        f"The {m} measured points started at the tool origin (their positions on the tool "
        "were not given) and were fitted."
    )


def _check_bounds(bounds: dict) -> dict:
    out = {}
    for name, pair in bounds.items():
        try:
            lo, hi = (float(v) for v in pair)
        except (TypeError, ValueError):
            raise CalibrationError(
                f"bounds[{name!r}] = {pair!r}; give (lower, upper) deviations in SI units"
            ) from None
        if np.isnan(lo) or np.isnan(hi) or not lo < hi:
            raise CalibrationError(f"bounds[{name!r}] = ({lo}, {hi}): lower must be below upper")
        out[name] = (lo, hi)
    return out


def _check_prior(prior: dict) -> dict:
    out = {}
    for name, sd in prior.items():
        try:
            sd = float(sd)
        except (TypeError, ValueError):
            raise CalibrationError(f"prior[{name!r}] = {sd!r} is not a number") from None
        if not (np.isfinite(sd) and sd > 0):
            raise CalibrationError(
                f"prior[{name!r}] = {sd}: a prior standard deviation must be finite and > 0 (SI)"
            )
        out[name] = sd
    return out
