"""Identification of parameter deviations from measured positions: `identify`.

Every method solves the same weighted least-squares problem in the deviations ``x`` of the
estimated parameters::

    minimise  0.5 Σ_i Σ_rows (r_i,row(p0 + x) / σ_i,row)²

whose rows per pose are the measured points' coordinates, ``y - f(q, p)`` (m), and, when
orientations were measured, the rotation vector ``log(R_meas R(q, p)ᵀ)`` (rad). Columns
of the Jacobian are scaled to unit norm before any factorisation, so metres and radians
do not decide the rank. Parameters the poses cannot separate are found first
(`casecal.observability`); a base set of the identifiable ones is estimated and the rest
are held at nominal (or at the start of the fit) and reported, never given arbitrary
values.
"""

from __future__ import annotations

import logging
import time
from collections import OrderedDict
from functools import partial

import numpy as np

from ..data.measurements import Measurements, broadcast_sigma
from ..errors import CalibrationError
from ..model.frames import rigid_fit, rpy_from_matrix
from ..model.robot import Robot
from .analysis import analyse, selection
from .calibration import STATUS_MESSAGES, Calibration
from .solvers import SOLVERS, Problem, nr_threshold, triangular

log = logging.getLogger(__name__)

METHODS = tuple(SOLVERS)


def identify(
    robot: Robot,
    measurements: Measurements,
    parameters=None,
    method: str = "svd",
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
) -> Calibration:
    """Identify the parameter deviations of `robot` from measured positions.

    Parameters
    ----------
    robot : Robot
        The nominal robot.
    measurements : Measurements
        Joint values and measured tool-point positions (m), with noise σ.
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
        ``"ipopt"`` only: lower and upper bound on the deviation of named parameters, SI.
    prior : dict of str to float, optional
        ``"ipopt"`` only: standard deviation (SI) of a Gaussian prior centred on the nominal
        value, per named parameter (regularisation toward nominal). Needs a measurement σ.
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
        1/√(1 + (e/c)²)), by iteratively reweighted least squares around `method`.
    loss_scale : float
        c: in units of the measurement σ when σ is given (default 3 σ), otherwise in units
        of the residuals' robust standard deviation (from their median).

    Returns
    -------
    Calibration

    Raises
    ------
    CalibrationError
        Unknown method or parameter, measurements of another robot, fewer measured
        coordinates than parameters to estimate, bounds or prior for a method without them.
    """
    t_start = time.perf_counter()
    if method not in METHODS:
        raise CalibrationError(f"unknown method {method!r}; use one of {', '.join(METHODS)}")
    if (bounds or prior) and method != "ipopt":
        raise CalibrationError("bounds and prior need method='ipopt'")
    bounds, prior = _check_bounds(bounds or {}), _check_prior(prior or {})
    if (
        isinstance(max_iterations, bool)
        or not isinstance(max_iterations, int)
        or max_iterations < 1
    ):
        raise CalibrationError(f"max_iterations must be a positive integer, got {max_iterations!r}")
    if not (isinstance(tolerance, int | float) and 0 < tolerance < 1):
        raise CalibrationError(f"tolerance must be a number between 0 and 1, got {tolerance!r}")
    names = selection(robot, parameters)
    if measurements.q.shape[1] != robot.dof:
        raise CalibrationError(
            f"measurements have {measurements.q.shape[1]} joint values per pose but robot "
            f"{robot.name!r} has {robot.dof} joints; use the robot the data came from"
        )
    q, y = measurements.q, measurements.points  # y: (N, m, 3)
    robot, point_note = _with_points(robot, measurements.n_points)
    names = selection(robot, parameters) if point_note else names
    sigma = measurements.sigma if noise is None else broadcast_sigma(noise, q.shape[0])
    known = bool(np.all(sigma > 0))
    if not known and np.any(sigma > 0):
        raise CalibrationError(
            "noise sigma is zero for some coordinates and not others; give every coordinate "
            "its sigma (> 0), or none (0 everywhere) to weigh all alike"
        )
    w = 1.0 / sigma if known else np.ones_like(sigma)
    R_meas = measurements.orientations
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
        if orientation_sigma > 0 and not known and R_meas is not None:
            # positions would weigh 1 per metre against 1/σ_rot per radian: ignored
            raise CalibrationError(
                "an orientation sigma needs the position sigma too (noise=... or a sigma_mm "
                "column); or give neither, and 1 mrad weighs like 0.1 mm"
            )
    if orientation_sigma:
        w_rot = 1.0 / orientation_sigma
    else:  # stated default: 1 mrad weighs like 0.1 mm
        w_rot = 0.1 * float(np.mean(w))
    make = partial(Problem, q=q, y=y, w=w, orientations=R_meas, w_rot=w_rot)
    if prior and not known:
        raise CalibrationError(
            "a prior needs the measurement sigma to weigh against; give noise=... (m) or "
            "measurements with sigma"
        )

    start, note = _starting_robot(robot, make, names)
    note = " ".join(t for t in (point_note, note) if t)
    solver = SOLVERS[method]
    kwargs = {"max_iterations": max_iterations, "tolerance": tolerance}
    if method == "ipopt":
        kwargs.update(bounds=bounds, prior=prior)
    if loss not in LOSSES:
        raise CalibrationError(f"unknown loss {loss!r}; use one of {', '.join(LOSSES)}")
    if not isinstance(loss_scale, int | float) or not (np.isfinite(loss_scale) and loss_scale > 0):
        raise CalibrationError(f"loss_scale must be a positive number, got {loss_scale!r}")
    obs, estimated = _analyse(make(start, names=names))
    base_problem = make(start, names=names).restricted(estimated)
    problem = base_problem
    weights = np.ones((q.shape[0], y.shape[1]))
    iterations, history = 0, []
    for _ in range(1 if loss == "linear" else 20):
        x, its, status, hist, message = solver(problem, np.zeros(len(estimated)), **kwargs)
        iterations += its
        history += hist if not history else hist[1:]
        start = start.with_deviations(dict(zip(estimated, x.tolist(), strict=True)))
        if loss == "linear" or status <= 0:
            break
        base_problem = make(start, names=names).restricted(estimated)
        e = np.linalg.norm(
            base_problem.point_residuals(np.zeros(len(estimated))) * w[:, None, :], axis=2
        )  # (N, m), in units of sigma (or m without sigma)
        c = loss_scale * (1.0 if known else _robust_sd(e))
        new = _loss_weights(loss, e, c)
        if np.abs(new - weights).max() < 1e-6:
            break
        weights = new
        problem = base_problem.reweighted(weights)
    outliers = _outliers(make(start, names=names).restricted(estimated), w)
    problem = make(start, names=names).restricted(estimated)
    if loss != "linear":
        problem = problem.reweighted(weights)
    x = np.zeros(len(estimated))

    # deviations are from the user's nominal robot; held parameters keep their start value
    p_nominal, p_final = robot.parameters, start.parameters
    deviations = {n: p_final[n] - p_nominal[n] for n in names}
    calibrated = start
    r_after = problem.residual(x)
    J = problem.jacobian(x)
    prior_w = np.array([1.0 / prior[n] if n in prior else 0.0 for n in estimated])
    cov, se = uncertainty(J, r_after, known, names, estimated, prior_w)
    cal = Calibration(
        method=method,
        nominal=robot,
        robot=calibrated,
        parameters=tuple(names),
        estimated=tuple(estimated),
        deviations=deviations,
        standard_errors=se,
        covariance=cov,
        residuals=problem.point_residuals(x).reshape(-1, 3),
        residuals_before=(y - robot.measured_points(q)).reshape(-1, 3),
        orientation_residuals=problem.orientation_residuals(x),
        outliers=outliers,
        loss=loss
        if loss == "linear"
        else f"{loss} (scale {loss_scale:g}{' sigma' if known else ' robust sd'})",
        iterations=iterations,
        status=status,
        message=message or STATUS_MESSAGES[status],
        history=tuple(float(h) for h in history),
        observability=obs,
        sigma_known=known,
        wall_time=time.perf_counter() - t_start,
        start_note=note,
    )
    return cal.compare_to(truth) if truth is not None else cal


LOSSES = ("linear", "huber", "soft_l1")


def _loss_weights(loss: str, e: np.ndarray, c: float) -> np.ndarray:
    """IRLS weights of residual norms `e` for a robust loss of scale `c`."""
    if loss == "huber":
        return np.where(e <= c, 1.0, c / np.maximum(e, 1e-300))
    return 1.0 / np.sqrt(1.0 + (e / c) ** 2)


def _robust_sd(e: np.ndarray) -> float:
    """Standard deviation of one coordinate from the median of point-residual norms.

    For Gaussian noise the norm of a 3-vector has median ≈ 1.538 σ.
    """
    return float(np.median(e)) / 1.538 or 1e-12


OUTLIER_THRESHOLD = 5.0
"""Robust standard deviations (1.4826 MAD) above the median that make a pose stand out."""


def _outliers(problem: Problem, w: np.ndarray) -> tuple[int, ...]:
    """Poses whose largest point residual stands out from the others.

    A pose is listed when its largest (σ-weighted) point-residual norm lies more than
    `OUTLIER_THRESHOLD` robust standard deviations above the median of all poses. The
    norm of Gaussian noise in 3-D has a long right tail, hence 5 rather than 3.
    """
    e = np.linalg.norm(
        problem.point_residuals(np.zeros(len(problem.names))) * w[:, None, :], axis=2
    ).max(axis=1)
    med = np.median(e)
    spread = 1.4826 * np.median(np.abs(e - med))
    if spread == 0:
        return ()
    return tuple(int(i) for i in np.flatnonzero(e > med + OUTLIER_THRESHOLD * spread))


def _with_points(robot: Robot, m: int) -> tuple[Robot, str]:
    """The robot with as many measured points as the data have (new ones at the origin)."""
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


def _prefit_frames(start: Robot, make, names) -> Robot:
    """Fit the base and tool frames alone before everything else.

    With the tool offset still at zero the measured point lies on the wrist's axes, and the
    wrist's twists look blind; fitting the (well-conditioned) frames first puts the
    linearisation where the whole identification can see what it should.
    """
    frames = [n for n in names if n.startswith(("base_", "tool_", "point"))]
    try:
        _, est = _analyse(make(start, names=frames))
    except CalibrationError:
        return start
    x, *_ = SOLVERS["gauss-newton"](
        make(start, names=frames).restricted(est),
        np.zeros(len(est)),
        max_iterations=50,
        tolerance=1e-10,
    )
    return start.with_deviations(dict(zip(est, x.tolist(), strict=True)))


def _starting_robot(robot: Robot, make, names) -> tuple[Robot, str]:
    """Where to linearise: the nominal robot, or with a base frame from a rigid fit.

    When base parameters are to be identified, the measured points may be in a far-away,
    turned instrument frame. A rigid fit of the nominal positions to the measured ones
    (`casecal.model.frames.rigid_fit`) gives a base frame close enough for Gauss-Newton, whatever
    the offset and angle; it is kept only if it lowers the residual.
    """
    base = [n for n in names if n.startswith("base_")]
    if not base:
        return robot, ""
    probe = make(robot, names=base)
    y, q, w = probe.y.reshape(-1, 3), probe.q, probe.w
    model = robot.measured_points(q).reshape(-1, 3)
    R, t = rigid_fit(model, y, weights=np.repeat(np.mean(w**2, axis=1), probe.m))
    fit = np.eye(4)
    fit[:3, :3], fit[:3, 3] = R, t
    T = fit @ robot.base.matrix()
    values = dict(zip(("base_x", "base_y", "base_z"), T[:3, 3].tolist(), strict=True))
    values.update(zip(("base_rx", "base_ry", "base_rz"), rpy_from_matrix(T[:3, :3]), strict=True))
    start = robot.with_parameters({n: values[n] for n in base})
    before = np.sum(probe.residual(np.zeros(len(base))) ** 2)
    after = np.sum(make(start, names=base).residual(np.zeros(len(base))) ** 2)
    if not after < before:
        return robot, ""
    start = _prefit_frames(start, make, names)
    moved = np.linalg.norm(T[:3, 3] - robot.base.matrix()[:3, 3])
    angle = np.degrees(np.arccos(np.clip((np.trace(fit[:3, :3]) - 1) / 2, -1.0, 1.0)))
    return start, (
        f"The base frame started from a rigid fit of the nominal positions to the measured "
        f"ones ({moved * 1e3:.1f} mm and {angle:.2f}° from the nominal base), then base and "
        "tool were fitted alone before all parameters; frame parameters the data cannot "
        "separate are held at that start."
    )


def _analyse(full: Problem):
    """Identifiability at `full`'s robot, and the base set to estimate (checked)."""
    obs = _nominal_analysis(full)
    names = full.names
    n_poses, rows = full.q.shape[0], full.w_flat.size
    if obs.rank >= rows and len(names) > obs.rank:
        # the data, not the robot's structure, limit what can be seen
        raise CalibrationError(
            f"{n_poses} poses give {rows} coordinates, fewer than the "
            f"{len(names)} parameters asked for, so they cannot tell which are blind; "
            f"measure at least {len(names) // 3 + 1} poses or ask for fewer parameters"
        )
    if not obs.base_parameters:
        raise CalibrationError(
            f"none of the asked-for parameters ({', '.join(names)}) moves the measured point at "
            "these poses; ask for others or measure other poses"
        )
    return obs, obs.base_parameters


_NOMINAL: OrderedDict = OrderedDict()
_NOMINAL_SIZE = 16


def _nominal_analysis(full: Problem):
    """Identifiability at nominal, shared by every fit of the same robot, poses and weights.

    Studies fit many noise realisations of the same poses: the nominal Jacobian and its
    analysis are computed once (LRU of `_NOMINAL_SIZE`) and seeded into `full`'s memo.
    """
    p0 = full.p0.tobytes()
    R = b"" if full.R is None else full.R.tobytes()
    key = (full.robot.structure, p0, full.q.tobytes(), full.w_flat.tobytes(), R, full.names)
    hit = _NOMINAL.get(key)
    if hit is None:
        obs = analyse(full.jacobian(np.zeros(len(full.names))), full.names, full.q.shape[0])
        memo = {k: v for k, v in full._memo.items() if k[1] == p0}
        hit = _NOMINAL[key] = (obs, memo)
        if len(_NOMINAL) > _NOMINAL_SIZE:
            _NOMINAL.popitem(last=False)
    else:
        _NOMINAL.move_to_end(key)
        full._memo.update(hit[1])
    return hit[0]


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


def uncertainty(J, r, known: bool, names, estimated, prior_w=None) -> tuple[np.ndarray, dict]:
    """Covariance of the estimated deviations and standard errors of all asked-for names
    (NaN for those held), from the weighted Jacobian `J` and residuals `r` at the solution."""
    cov = _covariance(J, r, known, prior_w)
    se = dict.fromkeys(names, float("nan"))
    se.update(zip(estimated, np.sqrt(np.diag(cov)).tolist(), strict=True))
    return cov, se


def _covariance(J: np.ndarray, r: np.ndarray, known: bool, prior_w=None) -> np.ndarray:
    """``(JᵀJ + W_p²)⁻¹`` of the weighted Jacobian and prior weights ``W_p = 1/σ_p``.

    Scaled by the residual variance ``RSS / (3N - k)`` when σ is unknown; NaN when there
    are no residual degrees of freedom to estimate it from.
    """
    k = J.shape[1]
    if k == 0:
        return np.zeros((0, 0))
    if prior_w is not None and np.any(prior_w > 0):
        J = np.vstack([J, np.diag(prior_w)])
    norms = np.linalg.norm(J, axis=0)
    norms[norms == 0] = 1.0
    _, s, Vt = np.linalg.svd(triangular(J / norms)[0], full_matrices=False)
    keep = s > nr_threshold(s, J.shape)
    inv = (Vt[keep].T / s[keep] ** 2) @ Vt[keep]
    cov = inv / np.outer(norms, norms)
    if not known:
        dof = r.size - k
        cov = cov * (float(r @ r) / dof if dof > 0 else np.nan)
    return cov
