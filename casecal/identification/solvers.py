"""The least-squares solvers behind `casecal.identify`, one function per method.

Each takes a `Problem` (weighted residuals and Jacobians of the deviations ``x`` of the
estimated parameters) and returns ``(x, iterations, status, history, message)`` with the
statuses of `casecal.identification.calibration.STATUS_MESSAGES`. The iterated solvers
stop when the step, or the cost decrease that the next Gauss-Newton step predicts, falls
under the tolerance, so a converged fit is not walked through a line search of tiny steps.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..errors import CalibrationError
from .linalg import gauss_newton_step, svd_solve
from .problem import Problem


def _svd(problem: Problem, x0, callback=None, **_):
    r0 = problem.residual(x0)
    x = x0 + svd_solve(problem.reduced(x0, r0))
    r1 = problem.residual(x)
    return x, 1, 1, [0.5 * r0 @ r0, 0.5 * r1 @ r1], None


STOP = 4 * np.finfo(float).eps
"""The solvers stop when residuals fall below this fraction of the largest coordinate."""

ROUNDING = 256 * np.finfo(float).eps
"""Residuals below this fraction of the largest measured coordinate are rounding (the
audit's floor): the forward kinematics of a seven-link chain loses some tens of ε in its
products, so a solver may stop above `STOP` with nothing left to gain."""


def floor_cost(problem: Problem, fraction: float = STOP) -> float:
    """Cost below which residuals are `fraction` of the largest measured coordinate."""
    return 0.5 * np.sum((fraction * np.abs(problem.y).max() * problem.w_flat) ** 2)


def _start(problem: Problem, x0):
    """Shared start of the iterated solvers: x, residual, cost, history, floor."""
    x = x0.copy()
    r = problem.residual(x)
    cost = 0.5 * r @ r
    return x, r, cost, [cost], floor_cost(problem)


def _converged(predicted: float, cost: float, tolerance: float, floor: float) -> bool:
    """Whether the cost decrease one more step predicts is negligible."""
    return predicted <= tolerance * cost + floor


STALL = 1e-3
"""A step that lowers the cost by less than this many residual variances changes nothing
the noise would let anyone see: along a nearly blind, curved valley, damped steps can
crawl like that for hundreds of iterations."""

CLOSE = 0.05
"""A stalled Gauss-Newton stops as converged when the next step promises less than this
many residual variances (well within the audit's bar); otherwise LM takes over."""


WATCH = 1.0
"""Residual variances per estimated parameter a Gauss-Newton step may promise at most for
its overshoot to be taken on watch (`_gauss_newton`). Far from the bottom, where a long
step may cross into another basin (a camera turned half a turn), it is halved at once."""


def _variance(problem: Problem, cost: float) -> float:
    """The residual variance (in the cost's units) at `cost`: 2 cost / (rows - k)."""
    dof = problem.observed_rows - len(problem.names)  # rows not measured: none
    return 2.0 * cost / max(dof, 1)


def _gauss_newton(problem: Problem, x0, max_iterations, tolerance, callback=None, **_):
    x, r, cost, history, floor = _start(problem, x0)
    # Near the bottom (a step promising at most `WATCH` residual variances a parameter),
    # a full step that raises the cost is taken once, on watch, and judged by the step
    # after it (Chamberlain's watchdog): along a curved, nearly blind valley the second
    # full step lands below where the first began, where halving the first crawls for
    # ten iterations. If it does not, the fit goes back and halves the first step.
    watch = None  # (x, r, cost, step, predicted, linear) where the step on watch began
    crawling = False  # the last step was halved: the next full one likely overshoots too
    for it in range(1, max_iterations + 1):
        linear = problem.reduced(x, r, exact=False)
        step, predicted = gauss_newton_step(linear)
        done = _converged(predicted, cost, tolerance, floor)
        bottom = predicted <= WATCH * len(step) * _variance(problem, cost)
        before = cost if watch is None else watch[2]  # the cost to beat
        x_new, t = x + step, 1.0
        # a full step likely taken comes with its Jacobian; not one likely halved
        r_new = problem.residual(x_new, ahead=not done and (bottom or not crawling))
        cost_new = 0.5 * r_new @ r_new
        if watch is None and bottom and not done and np.isfinite(cost_new) and cost_new >= cost:
            watch = (x, r, cost, step, predicted, linear)
            x, r, cost = x_new, r_new, cost_new
            history.append(cost)
            if callback is not None:
                callback(it, cost)
            continue
        if not cost_new < before and (watch is not None or not done):
            if watch is not None:  # back to where the step on watch began (not done there)
                x, r, cost, step, predicted, linear = watch
                done = False
            x_new, r_new, cost_new, t = _halved(problem, x, step, cost)
        watch, crawling = None, t < 1.0
        if cost_new < before:
            norms = linear.norms
            small = np.linalg.norm(t * step * norms) <= tolerance * (
                np.linalg.norm(x * norms) + tolerance
            )
            stalled = before - cost_new <= STALL * _variance(problem, cost_new)
            x, r, cost = x_new, r_new, cost_new
            history.append(cost)
            if callback is not None:
                callback(it, cost)
            if cost <= floor:
                return x, it, 4, history, None
            if small or done:
                return x, it, 2, history, None
            if stalled:  # crawling: converged if little is left, else let LM go on
                near = predicted <= CLOSE * _variance(problem, cost)
                return x, it, 2 if near else 3, history, None
        else:
            history.append(cost)
            return x, it, 2 if done else 3, history, None
    if watch is not None:  # out of iterations on watch: where it began, cost lower
        x, cost = watch[0], watch[2]
        history[-1] = cost
        if callback is not None:
            callback(max_iterations, cost)
    return x, max_iterations, 0, history, None


def _halved(problem: Problem, x, step, cost: float):
    """The damped Gauss-Newton trial: ``x + t step`` for t = 1/2, 1/4, … until the cost
    goes below `cost` (or t < 1e-3); (x, r, cost, t) there."""
    t = 0.5
    while True:
        x_new = x + t * step
        r_new = problem.residual(x_new)
        cost_new = 0.5 * r_new @ r_new
        if cost_new < cost or t < 1e-3:
            return x_new, r_new, cost_new, t
        t *= 0.5


def _levenberg_marquardt(problem: Problem, x0, max_iterations, tolerance, callback=None, **_):
    x, r, cost, history, floor = _start(problem, x0)
    linear = problem.reduced(x, r, exact=False)
    norms = linear.norms
    norms[norms == 0] = 1.0
    mu, nu, stalls = None, 2.0, 0
    for it in range(1, max_iterations + 1):
        Rs = linear.R / norms  # work in scaled variables z = x * norms
        A = Rs.T @ Rs  # JᵀJ and Jᵀr from the R factor of [J | r]
        g = Rs.T @ linear.Qtr
        # the undamped step's predicted decrease, from the normal equations: a
        # convergence test only, so their squared condition number does no harm
        h_gn = np.linalg.lstsq(A, g, rcond=1e-12)[0]
        promised = 0.5 * float(g @ h_gn)
        if _converged(promised, cost, tolerance, floor) or (
            stalls and promised <= CLOSE * _variance(problem, cost)
        ):
            # nothing measurable left to gain: take the undamped step if it helps, stop
            r_gn = problem.residual(x + h_gn / norms)
            if 0.5 * r_gn @ r_gn < cost:
                x, cost = x + h_gn / norms, 0.5 * r_gn @ r_gn
            history.append(cost)
            return x, it, 4 if cost <= floor else 2, history, None
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
            stalls = stalls + 1 if cost - cost_new <= STALL * _variance(problem, cost_new) else 0
            x, r, cost = x_new, r_new, cost_new
            history.append(cost)
            if callback is not None:
                callback(it, cost)
            if cost <= floor:
                return x, it, 4, history, None
            if small or stalls >= 3:  # three steps in a row that change nothing visible
                return x, it, 2, history, None
            linear = problem.reduced(x, r, exact=False)
            mu *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
            nu = 2.0
        else:
            history.append(cost)
            if small:  # even a tiny step does not lower the cost: rounding floor
                return x, it, 3, history, None
            mu *= nu
            nu *= 2.0
    return x, max_iterations, 0, history, None


class _LeastSquares:
    """Objective ``0.5 (|r(z)|² + |w_p z|²) / scale``, its gradient and Gauss-Newton Hessian.

    ``z = x · norms`` are the column-scaled deviations; ``w_p`` the prior's weights, the
    prior centred on nominal, ``z_0`` from the start of this fit. The reduction at the last
    point is memoised by the problem, since IPOPT asks for gradient and Hessian there.
    """

    def __init__(self, problem: Problem, norms, scale, prior_w, z0):
        self.problem, self.norms, self.scale, self.prior_w = problem, norms, scale, prior_w
        self.z0 = z0

    def _scaled(self, z):
        """(R / norms, Qᵀr) of the weighted ``[J | r]`` at `z` (memoised by the problem)."""
        linear = self.problem.reduced(z / self.norms, exact=False)
        return linear.R / self.norms, linear.Qtr

    def value(self, z):
        r = self.problem.residual(z / self.norms)
        return 0.5 * (r @ r + np.sum((self.prior_w * (z + self.z0)) ** 2)) / self.scale

    def gradient(self, z):
        Rs, Qtr = self._scaled(z)  # Jᵀr = Rᵀ Qᵀr
        return (-Rs.T @ Qtr + self.prior_w**2 * (z + self.z0)) / self.scale

    def hessian(self, z):
        Rs, _ = self._scaled(z)
        return (Rs.T @ Rs + np.diag(self.prior_w**2)) / self.scale


class _Callback(ca.Callback):
    """A CasADi Function of dense inputs evaluated in Python (by compiled kernels)."""

    def __init__(self, name, inputs, output, evaluate, jacobian=None):
        ca.Callback.__init__(self)
        self._inputs, self._output = inputs, output
        self._evaluate, self._jacobian_factory, self._keep = evaluate, jacobian, None
        self.construct(name, {"enable_fd": False})

    def get_n_in(self):
        return len(self._inputs)

    def get_n_out(self):
        return 1

    def get_sparsity_in(self, i):
        return self._inputs[i]

    def get_sparsity_out(self, i):
        return self._output

    def eval(self, arg):
        return [self._evaluate(*[np.array(a, dtype=float).ravel() for a in arg])]

    def has_jacobian(self):
        return self._jacobian_factory is not None

    def get_jacobian(self, name, inames, onames, opts):
        self._keep = self._jacobian_factory(name)  # CasADi does not own Python callbacks
        return self._keep


def _ipopt(
    problem: Problem,
    x0,
    max_iterations,
    tolerance,
    bounds,
    prior,
    prior_offset=None,
    callback=None,
):
    """IPOPT on the scaled problem, objective normalised by its start value, GN Hessian.

    The objective, its gradient and the Gauss-Newton Hessian ``JᵀJ`` are CasADi Callbacks
    that evaluate through the compiled kernels, so IPOPT never runs the graph in CasADi's
    interpreter and no graph over all poses is built.
    """
    k = len(problem.names)
    for name in {**bounds, **prior}:
        if name not in problem.names:
            raise CalibrationError(
                f"bounds/prior name {name!r} is not among the estimated parameters "
                f"({', '.join(problem.names)})"
            )
    r0 = problem.residual(x0)
    norms = problem.reduced(x0, r0).norms
    norms[norms == 0] = 1.0
    scale = max(0.5 * r0 @ r0, floor_cost(problem))
    sig = np.array([prior.get(name, np.inf) for name in problem.names])
    prior_w = np.where(np.isfinite(sig), 1.0 / sig, 0.0) / norms  # per z
    z0 = np.zeros(k) if prior_offset is None else prior_offset * norms
    ls = _LeastSquares(problem, norms, scale, prior_w, z0)
    dense = ca.Sparsity.dense
    z_sp, scalar, empty = dense(k, 1), dense(1, 1), dense(0, 1)
    gradient = _Callback(
        "casecal_grad_f", [z_sp, scalar], dense(1, k), lambda z, f: ca.DM(ls.gradient(z)).T
    )
    objective = _Callback(
        "casecal_f", [z_sp], scalar, lambda z: ca.DM(ls.value(z)), jacobian=lambda name: gradient
    )
    hessian = _Callback(
        "nlp_hess_l",
        [z_sp, empty, scalar, empty],
        ca.Sparsity.upper(k),
        lambda z, p, lam_f, lam_g: ca.triu(ca.DM(lam_f[0] * ls.hessian(z))),
    )
    z = ca.MX.sym("z", k)
    solver = ca.nlpsol(
        "casecal_ipopt",
        "ipopt",
        {"x": z, "f": objective(z)},
        {
            "hess_lag": hessian,
            "print_time": False,
            "ipopt.print_level": 0,
            "ipopt.sb": "yes",
            "ipopt.max_iter": max_iterations,
            "ipopt.tol": max(tolerance, 1e-10),  # the scaled gradient's rounding floor is ~1e-11
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
    elif stats.get("return_status") == "Search_Direction_Becomes_Too_Small":
        status, message = 3, None  # no step lowers the cost: the audit judges optimality
    return x_opt, int(stats.get("iter_count", 0)), status, history, message


SOLVERS = {
    "svd": _svd,
    "gauss-newton": _gauss_newton,
    "lm": _levenberg_marquardt,
    "ipopt": _ipopt,
}
