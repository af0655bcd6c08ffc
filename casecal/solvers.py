"""The least-squares solvers behind `casecal.identify`, one function per method.

Each takes a `Problem` (weighted residuals and Jacobians of the deviations ``x`` of the
estimated parameters) and returns ``(x, iterations, status, history, message)`` with the
statuses of `casecal.calibration.STATUS_MESSAGES`.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from . import kinematics
from .errors import CalibrationError
from .robot import Robot


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


SOLVERS = {
    "svd": _svd,
    "gauss-newton": _gauss_newton,
    "lm": _levenberg_marquardt,
    "ipopt": _ipopt,
}
