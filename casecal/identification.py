"""Identification of parameter deviations from measured positions: `identify`.

Every method solves the same weighted least-squares problem in the deviations ``x`` of the
estimated parameters::

    minimise  0.5 Σ_i Σ_axis ((y_i - f(q_i, p0 + x)) / σ_i,axis)²

with ``f`` the tool-point position. Columns of the Jacobian are scaled to unit norm before
any factorisation, so metres and radians do not decide the rank. Parameters the poses cannot
separate are found first (`casecal.observability`); a base set of the identifiable ones is
estimated and the rest are held at nominal and reported, never given arbitrary values.
"""

from __future__ import annotations

import logging
import time

import casadi as ca
import numpy as np

from . import kinematics
from .calibration import STATUS_MESSAGES, Calibration
from .errors import CalibrationError
from .identifiability import analyse, selection
from .measurements import Measurements
from .robot import Robot

log = logging.getLogger(__name__)

METHODS = ("svd", "gauss-newton", "lm", "ipopt")


def nr_threshold(s: np.ndarray, shape: tuple[int, int]) -> float:
    """Numerical Recipes' singular-value cut-off: ``0.5 √(m + n + 1) · s_max · ε``.

    Singular values below it are rounding noise and are set to zero in the pseudo-inverse
    (Press et al., *Numerical Recipes*, 3rd ed., §2.6), as the paper does.
    """
    m, n = shape
    return 0.5 * np.sqrt(m + n + 1.0) * (s[0] if s.size else 0.0) * np.finfo(float).eps


def svd_solve(J: np.ndarray, r: np.ndarray) -> np.ndarray:
    """``x = D V S⁺ Uᵀ r`` for the column-scaled ``J D``: the paper's SVD least squares."""
    norms = np.linalg.norm(J, axis=0)
    norms[norms == 0] = 1.0
    U, s, Vt = np.linalg.svd(J / norms, full_matrices=False)
    keep = s > nr_threshold(s, J.shape)
    z = Vt[keep].T @ ((U[:, keep].T @ r) / s[keep])
    return z / norms


class Problem:
    """Weighted residuals and Jacobians of the deviations ``x`` of chosen parameters."""

    def __init__(self, robot: Robot, q: np.ndarray, y: np.ndarray, w: np.ndarray, names):
        self.robot = robot
        self.chain = kinematics.chain(robot.structure)
        self.q, self.y, self.w = q, y, w
        self.names = tuple(names)
        self.columns = self.chain.columns(self.names)
        self.p0 = robot.vector()
        self.w_flat = w.ravel()

    def p(self, x: np.ndarray) -> np.ndarray:
        p = self.p0.copy()
        p[list(self.columns)] += x
        return p

    def residual(self, x: np.ndarray) -> np.ndarray:
        """Weighted ``y - f``, shape (3N,), pose-major."""
        f = self.chain.evaluate("position", self.q, self.p(x))
        return ((self.y - f) * self.w).ravel()

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        """Weighted ``∂f/∂x``, shape (3N, k)."""
        J = self.chain.evaluate("position_jacobian", self.q, self.p(x), self.columns)
        return J.reshape(-1, len(self.names)) * self.w_flat[:, None]


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
    names = selection(robot, parameters)
    if measurements.q.shape[1] != robot.dof:
        raise CalibrationError(
            f"measurements have {measurements.q.shape[1]} joint values per pose but robot "
            f"{robot.name!r} has {robot.dof} joints; use the robot the data came from"
        )
    q, y = measurements.q, measurements.positions
    sigma = measurements.sigma if noise is None else _sigma(noise, q.shape[0])
    known = bool(np.all(sigma > 0))
    if not known and np.any(sigma > 0):
        raise CalibrationError("noise sigma is zero for some coordinates and not others")
    w = 1.0 / sigma if known else np.ones_like(y)
    if prior and not known:
        raise CalibrationError(
            "a prior needs the measurement sigma to weigh against; give noise=... (m) or "
            "measurements with sigma"
        )

    full = Problem(robot, q, y, w, names)
    obs = analyse(full.jacobian(np.zeros(len(names))), names, n_poses=q.shape[0])
    estimated = obs.base_parameters
    if obs.rank >= 3 * q.shape[0] and len(names) > obs.rank:
        # the data, not the robot's structure, limit what can be seen
        raise CalibrationError(
            f"{q.shape[0]} poses give {3 * q.shape[0]} coordinates, fewer than the "
            f"{len(names)} parameters asked for, so they cannot tell which are blind; "
            f"measure at least {len(names) // 3 + 1} poses or ask for fewer parameters"
        )
    problem = Problem(robot, q, y, w, estimated)
    x0 = np.zeros(len(estimated))
    solver = {
        "svd": _svd,
        "gauss-newton": _gauss_newton,
        "lm": _levenberg_marquardt,
        "ipopt": _ipopt,
    }[method]
    kwargs = {"max_iterations": max_iterations, "tolerance": tolerance}
    if method == "ipopt":
        kwargs.update(bounds=bounds or {}, prior=prior or {})
    x, iterations, status, history, message = solver(problem, x0, **kwargs)

    deviations = dict.fromkeys(names, 0.0)
    deviations.update(zip(estimated, x.tolist(), strict=True))
    calibrated = robot.with_deviations({n: deviations[n] for n in estimated})
    r_after = problem.residual(x)
    J = problem.jacobian(x)
    cov = _covariance(J, r_after, known)
    se = dict.fromkeys(names, float("nan"))
    se.update(zip(estimated, np.sqrt(np.diag(cov)).tolist(), strict=True))
    cal = Calibration(
        method=method,
        nominal=robot,
        robot=calibrated,
        parameters=tuple(names),
        estimated=tuple(estimated),
        deviations=deviations,
        standard_errors=se,
        covariance=cov,
        residuals=(r_after / w.ravel()).reshape(-1, 3),
        residuals_before=y - robot.position(q),
        iterations=iterations,
        status=status,
        message=message or STATUS_MESSAGES[status],
        history=tuple(float(h) for h in history),
        observability=obs,
        sigma_known=known,
        wall_time=time.perf_counter() - t_start,
    )
    return cal.compare_to(truth) if truth is not None else cal


def _sigma(noise, n: int) -> np.ndarray:
    try:
        arr = np.asarray(noise, dtype=float)
        sigma = np.broadcast_to(arr if arr.ndim != 1 or arr.size == 3 else arr[:, None], (n, 3))
    except ValueError:
        raise CalibrationError(
            f"noise must be a scalar, 3 values (x, y, z) or one per pose, in m; got {noise!r}"
        ) from None
    if not np.all(np.isfinite(sigma)) or np.any(sigma < 0):
        raise CalibrationError("noise sigma must be finite and non-negative (m)")
    return sigma.copy()


def _covariance(J: np.ndarray, r: np.ndarray, known: bool) -> np.ndarray:
    """``(JᵀJ)⁻¹`` of the weighted Jacobian, times the residual variance when σ is unknown."""
    k = J.shape[1]
    if k == 0:
        return np.zeros((0, 0))
    norms = np.linalg.norm(J, axis=0)
    norms[norms == 0] = 1.0
    _, s, Vt = np.linalg.svd(J / norms, full_matrices=False)
    keep = s > nr_threshold(s, J.shape)
    inv = (Vt[keep].T / s[keep] ** 2) @ Vt[keep]
    cov = inv / np.outer(norms, norms)
    if not known:
        dof = max(J.shape[0] - k, 1)
        cov = cov * float(r @ r) / dof
    return cov


# --- solvers: each returns (x, iterations, status, history, message) -------------------


def _svd(problem: Problem, x0, **_):
    r0 = problem.residual(x0)
    x = x0 + svd_solve(problem.jacobian(x0), r0)
    r1 = problem.residual(x)
    return x, 1, 1, [0.5 * r0 @ r0, 0.5 * r1 @ r1], None


def _floor(problem: Problem) -> float:
    """Cost below which the residuals are rounding noise of the measured coordinates."""
    eps = np.finfo(float).eps
    return 0.5 * np.sum((4 * eps * np.abs(problem.y).max() * problem.w_flat) ** 2)


def _gauss_newton(problem: Problem, x0, max_iterations, tolerance, **_):
    x = x0.copy()
    r = problem.residual(x)
    cost = 0.5 * r @ r
    history = [cost]
    floor = _floor(problem)
    for it in range(1, max_iterations + 1):
        J = problem.jacobian(x)
        step = svd_solve(J, r)
        t = 1.0
        while True:  # halve the step until the cost goes down (damped Gauss-Newton)
            x_new = x + t * step
            r_new = problem.residual(x_new)
            cost_new = 0.5 * r_new @ r_new
            if cost_new < cost or t < 1e-3:
                break
            t *= 0.5
        if cost_new >= cost:
            history.append(cost)
            return x, it, 3, history, None
        norms = np.linalg.norm(J, axis=0)
        small = np.linalg.norm(t * step * norms) <= tolerance * (
            np.linalg.norm(x * norms) + tolerance
        )
        x, r, cost = x_new, r_new, cost_new
        history.append(cost)
        if cost <= floor:
            return x, it, 4, history, None
        if small:
            return x, it, 2, history, None
    return x, max_iterations, 0, history, None


def _levenberg_marquardt(problem: Problem, x0, max_iterations, tolerance, **_):
    x = x0.copy()
    r = problem.residual(x)
    cost = 0.5 * r @ r
    history = [cost]
    floor = _floor(problem)
    J = problem.jacobian(x)
    norms = np.linalg.norm(J, axis=0)
    norms[norms == 0] = 1.0
    mu, nu = None, 2.0
    for it in range(1, max_iterations + 1):
        Js = J / norms  # work in scaled variables z = x * norms
        A = Js.T @ Js
        g = Js.T @ r
        if mu is None:
            mu = 1e-6 * float(np.max(np.diag(A)))
        h = np.linalg.solve(A + mu * np.eye(len(g)), g)
        dx = h / norms
        x_new = x + dx
        r_new = problem.residual(x_new)
        cost_new = 0.5 * r_new @ r_new
        predicted = 0.5 * h @ (mu * h + g)
        rho = (cost - cost_new) / predicted if predicted > 0 else -1.0
        small = np.linalg.norm(h) <= tolerance * (np.linalg.norm(x * norms) + tolerance)
        if rho > 0:
            x, r, cost = x_new, r_new, cost_new
            history.append(cost)
            if cost <= floor:
                return x, it, 4, history, None
            if small:
                return x, it, 2, history, None
            J = problem.jacobian(x)
            mu *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
            nu = 2.0
        else:
            history.append(cost)
            if small:  # even a tiny step does not lower the cost: rounding floor
                return x, it, 3, history, None
            mu *= nu
            nu *= 2.0
    return x, max_iterations, 0, history, None


def _ipopt(problem: Problem, x0, max_iterations, tolerance, bounds, prior):
    """IPOPT on the scaled problem, objective normalised by its start value, GN Hessian."""
    ch, k, n = problem.chain, len(problem.names), problem.q.shape[0]
    for name in {**bounds, **prior}:
        if name not in problem.names:
            raise CalibrationError(
                f"bounds/prior name {name!r} is not among the estimated parameters "
                f"({', '.join(problem.names)})"
            )
    J0 = problem.jacobian(x0)
    norms = np.linalg.norm(J0, axis=0)
    norms[norms == 0] = 1.0
    r0 = problem.residual(x0)
    scale = max(0.5 * r0 @ r0, _floor(problem))

    z = ca.MX.sym("z", k)
    x = z / norms
    p = ca.MX(problem.p0)
    p = p + ca.MX(_selector(len(problem.p0), problem.columns)) @ x
    angles = p[ch.angle_index]
    pext = ca.vertcat(p, ca.cos(angles), ca.sin(angles))
    Q = ca.DM(problem.q.T)
    W = ca.DM(problem.w.T)
    f_pos = ch.function("position").map(n)
    f_jac = ch.function("position_jacobian", problem.columns).map(n)
    res = W * (ca.DM(problem.y.T) - f_pos(Q, pext))  # 3 × N
    sig = np.array([prior.get(name, np.inf) for name in problem.names])
    prior_w = np.where(np.isfinite(sig), 1.0 / sig, 0.0) / norms  # per z
    cost = 0.5 * ca.sumsqr(res) + 0.5 * ca.sumsqr(prior_w * z)
    Jt = f_jac(Q, pext) * ca.repmat(ca.reshape(W, 1, 3 * n), k, 1)  # k × 3N, ∂f/∂x
    Jz = Jt / ca.repmat(ca.DM(norms), 1, 3 * n)
    lam_f = ca.MX.sym("lam_f")
    H = lam_f * (Jz @ Jz.T + ca.diag(prior_w**2)) / scale
    hess = ca.Function(
        "nlp_hess_l", [z, ca.MX.sym("p", 0), lam_f, ca.MX.sym("lam_g", 0)], [ca.triu(H)]
    )
    solver = ca.nlpsol(
        "casecal_ipopt",
        "ipopt",
        {"x": z, "f": cost / scale},
        {
            "hess_lag": hess,
            "print_time": False,
            "ipopt.print_level": 0,
            "ipopt.sb": "yes",
            "ipopt.max_iter": max_iterations,
            "ipopt.tol": 1e-10,  # the scaled gradient's rounding floor is ~1e-11
            "ipopt.acceptable_iter": 0,
            "ipopt.bound_relax_factor": 0.0,  # bounds the user gave hold exactly
        },
    )
    lb = np.full(k, -np.inf)
    ub = np.full(k, np.inf)
    for name, (lo, hi) in bounds.items():
        i = problem.names.index(name)
        lb[i], ub[i] = lo * norms[i], hi * norms[i]
    sol = solver(x0=x0 * norms, lbx=lb, ubx=ub)
    stats = solver.stats()
    x_opt = np.array(sol["x"]).ravel() / norms
    history = [scale * f for f in stats.get("iterations", {}).get("obj", [])]
    if not history:
        r = problem.residual(x_opt)
        history = [0.5 * r0 @ r0, 0.5 * r @ r]
    ok = stats.get("success", False)
    status = 5 if ok else -1
    message = None if ok else f"failed: IPOPT returned {stats.get('return_status')}"
    if stats.get("return_status") == "Maximum_Iterations_Exceeded":
        status, message = 0, None
    return x_opt, int(stats.get("iter_count", 0)), status, history, message


def _selector(n: int, columns) -> np.ndarray:
    E = np.zeros((n, len(columns)))
    E[list(columns), range(len(columns))] = 1.0
    return E
