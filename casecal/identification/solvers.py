"""The least-squares solvers behind `casecal.identify`, one function per method.

Each takes a `Problem` (weighted residuals and Jacobians of the deviations ``x`` of the
estimated parameters) and returns ``(x, iterations, status, history, message)`` with the
statuses of `casecal.calibration.STATUS_MESSAGES`.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..data.measurements import rotation_vector
from ..errors import CalibrationError
from ..model import kinematics
from ..model.robot import Robot


def nr_threshold(s: np.ndarray, shape: tuple[int, int]) -> float:
    """Numerical Recipes' singular-value cut-off: ``0.5 √(m + n + 1) · s_max · ε``.

    Singular values below it are rounding noise and are set to zero in the pseudo-inverse
    (Press et al., *Numerical Recipes*, 3rd ed., §2.6), as the paper does.
    """
    m, n = shape
    return 0.5 * np.sqrt(m + n + 1.0) * (s[0] if s.size else 0.0) * np.finfo(float).eps


def triangular(J: np.ndarray, r: np.ndarray | None = None):
    """Reduce a tall ``J`` (and ``r``) to the R factor of its QR decomposition.

    ``J = Q R`` keeps every inner product of columns (``JᵀJ = RᵀR``), so the singular values,
    right singular vectors and least-squares solution of ``J`` are those of the small R,
    with ``Qᵀ r`` in place of ``r``. QR of ``[J | r]`` gives both at once, several times
    faster than an SVD of the tall ``J``.

    Returns
    -------
    R : ndarray, shape (min(m, k), k)
    Qtr : ndarray, shape (min(m, k),) or None
    """
    m, k = J.shape
    if r is None:
        return (np.linalg.qr(J, mode="r") if m > k else J), None
    if m <= k:
        return J, r
    Ra = np.linalg.qr(np.column_stack([J, r]), mode="r")
    return Ra[:k, :k], Ra[:k, k]


def svd_solve(J: np.ndarray, r: np.ndarray) -> np.ndarray:
    """``x = D V S⁺ Uᵀ r`` for the column-scaled ``J D``: the paper's SVD least squares.

    Computed on the R factor of ``J D`` (`triangular`): the same singular values and V.
    """
    norms = np.linalg.norm(J, axis=0)
    norms[norms == 0] = 1.0
    R, Qtr = triangular(J / norms, r)
    U, s, Vt = np.linalg.svd(R, full_matrices=False)
    keep = s > nr_threshold(s, J.shape)
    z = Vt[keep].T @ ((U[:, keep].T @ Qtr) / s[keep])
    return z / norms


class Problem:
    """Weighted residuals and Jacobians of the deviations ``x`` of chosen parameters.

    Per pose the residual stacks the m measured points (3m rows, m) and, when orientations
    were measured, the rotation vector ``log(R_meas R_modelᵀ)`` (3 rows, rad), each row
    divided by its σ.

    Parameters
    ----------
    robot : Robot
        The robot to linearise at.
    q : ndarray, shape (N, dof)
    y : ndarray, shape (N, 3) or (N, m, 3)
        Measured positions, m (m must match the robot's points; 1 without points).
    w : ndarray, shape (N, 3)
        Position weights 1/σ per pose and axis, shared by a pose's points.
    names : sequence of str
        The parameters whose deviations are ``x``.
    kernel_names : sequence of str, optional
        A superset of `names` to evaluate Jacobians for (then sliced): one compiled kernel
        then serves both the identifiability analysis of all asked-for parameters and the
        fit of their base set.
    orientations : ndarray, shape (N, 3, 3), optional
        Measured tool rotations.
    w_rot : float
        Orientation weight 1/σ_rot, 1/rad.
    """

    def __init__(
        self, robot: Robot, q, y, w, names, kernel_names=None, orientations=None, w_rot: float = 0.0
    ):
        self.robot = robot
        self.chain = kinematics.chain(robot.structure)
        n = q.shape[0]
        self.q = q
        self.y = np.asarray(y, dtype=float).reshape(n, -1)  # (N, 3m)
        self.m = self.y.shape[1] // 3
        self.w = w
        self.names = tuple(names)
        kernel_names = tuple(kernel_names or names)
        self.columns = self.chain.columns(self.names)
        self.kernel_columns = self.chain.columns(kernel_names)
        self.take = [kernel_names.index(n) for n in self.names]
        self.p0 = robot.vector()
        self.R = orientations
        self.w_rot = float(w_rot)
        rows = [np.tile(w, (1, self.m))]
        if orientations is not None:
            rows.append(np.full((n, 3), self.w_rot))
        self.w_rows = np.hstack(rows)  # (N, rows per pose)
        self.w_flat = self.w_rows.ravel()
        self._memo: dict = {}  # (kind, p bytes) -> array; shared with `restricted` copies

    def reweighted(self, point_weights: np.ndarray) -> Problem:
        """The same problem with each measured point's rows scaled by √weight (N, m).

        For iteratively reweighted least squares (robust losses); orientation rows keep
        the weight of the pose's least-trusted point.
        """
        other = self.restricted(self.names)
        scale = np.sqrt(np.repeat(point_weights, 3, axis=1))
        if self.R is not None:
            scale = np.hstack([scale, np.repeat(scale.min(axis=1, keepdims=True), 3, axis=1)])
        other.w_rows = self.w_rows * scale
        other.w_flat = other.w_rows.ravel()
        other._memo = self._memo
        return other

    def restricted(self, names) -> Problem:
        """The same data and kernel for a subset of the parameters (shares the memo)."""
        other = Problem.__new__(Problem)
        other.__dict__.update(self.__dict__)
        other.names = tuple(names)
        other.columns = self.chain.columns(other.names)
        kernel_names = [self.chain.names[c] for c in self.kernel_columns]
        other.take = [kernel_names.index(n) for n in other.names]
        return other

    def _evaluate(self, kind: str, p: np.ndarray) -> np.ndarray:
        # solvers, the identifiability analysis and the result ask for the same points
        key = (kind, p.tobytes())
        value = self._memo.get(key)
        if value is None:
            columns = self.kernel_columns if kind.endswith("jacobian") else ()
            value = self.chain.evaluate(kind, self.q, p, columns)
            if len(self._memo) >= 8:
                self._memo.pop(next(iter(self._memo)))
            self._memo[key] = value
        return value

    def p(self, x: np.ndarray) -> np.ndarray:
        p = self.p0.copy()
        p[list(self.columns)] += x
        return p

    def point_residuals(self, x: np.ndarray) -> np.ndarray:
        """Unweighted ``y - f`` of the points, shape (N, m, 3), m."""
        f = self._evaluate("points", self.p(x))
        return (self.y - f).reshape(len(self.q), self.m, 3)

    def orientation_residuals(self, x: np.ndarray) -> np.ndarray | None:
        """Unweighted ``log(R_meas R_modelᵀ)``, shape (N, 3), rad; None without data."""
        if self.R is None:
            return None
        R_model = self._evaluate("fk", self.p(x))[:, :3, :3]
        return rotation_vector(self.R @ np.swapaxes(R_model, 1, 2))

    def residual(self, x: np.ndarray) -> np.ndarray:
        """Weighted residuals, shape (N · rows per pose,), pose-major."""
        parts = [self.point_residuals(x).reshape(len(self.q), -1)]
        if self.R is not None:
            parts.append(self.orientation_residuals(x))
        return (np.hstack(parts) * self.w_rows).ravel()

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        """Weighted ``∂f/∂x``, shape (N · rows per pose, k)."""
        p = self.p(x)
        k = len(self.kernel_columns)
        parts = [self._evaluate("points_jacobian", p)]  # (N, 3m, k)
        if self.R is not None:
            parts.append(self._evaluate("pose_jacobian", p)[:, 3:, :])  # rotation rows
        J = np.concatenate(parts, axis=1).reshape(-1, k)
        if len(self.take) != J.shape[1]:
            J = J[:, self.take]
        return J * self.w_flat[:, None]


def _svd(problem: Problem, x0, **_):
    r0 = problem.residual(x0)
    x = x0 + svd_solve(problem.jacobian(x0), r0)
    r1 = problem.residual(x)
    return x, 1, 1, [0.5 * r0 @ r0, 0.5 * r1 @ r1], None


def _floor(problem: Problem) -> float:
    """Cost below which the residuals are rounding noise of the measured coordinates."""
    eps = np.finfo(float).eps
    return 0.5 * np.sum((4 * eps * np.abs(problem.y).max() * problem.w_flat) ** 2)


def _start(problem: Problem, x0):
    """Shared start of the iterated solvers: x, residual, cost, history, floor."""
    x = x0.copy()
    r = problem.residual(x)
    cost = 0.5 * r @ r
    return x, r, cost, [cost], _floor(problem)


def _gauss_newton(problem: Problem, x0, max_iterations, tolerance, **_):
    x, r, cost, history, floor = _start(problem, x0)
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
    x, r, cost, history, floor = _start(problem, x0)
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


class _LeastSquares:
    """Objective ``0.5 (|r(z)|² + |w_p z|²) / scale``, its gradient and Gauss-Newton Hessian.

    ``z = x · norms`` are the column-scaled deviations; ``w_p`` the prior's weights. The
    Jacobian at the last point is kept, since IPOPT asks for gradient and Hessian at the
    same point.
    """

    def __init__(self, problem: Problem, norms, scale, prior_w):
        self.problem, self.norms, self.scale, self.prior_w = problem, norms, scale, prior_w
        self._at, self._J = None, None

    def _jacobian(self, z):
        if self._at is None or not np.array_equal(z, self._at):
            self._at, self._J = z.copy(), self.problem.jacobian(z / self.norms) / self.norms
        return self._J

    def value(self, z):
        r = self.problem.residual(z / self.norms)
        return 0.5 * (r @ r + np.sum((self.prior_w * z) ** 2)) / self.scale

    def gradient(self, z):
        r = self.problem.residual(z / self.norms)
        return (-self._jacobian(z).T @ r + self.prior_w**2 * z) / self.scale

    def hessian(self, z):
        J = self._jacobian(z)
        return (J.T @ J + np.diag(self.prior_w**2)) / self.scale


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


def _ipopt(problem: Problem, x0, max_iterations, tolerance, bounds, prior):
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
    norms = np.linalg.norm(problem.jacobian(x0), axis=0)
    norms[norms == 0] = 1.0
    r0 = problem.residual(x0)
    scale = max(0.5 * r0 @ r0, _floor(problem))
    sig = np.array([prior.get(name, np.inf) for name in problem.names])
    prior_w = np.where(np.isfinite(sig), 1.0 / sig, 0.0) / norms  # per z
    ls = _LeastSquares(problem, norms, scale, prior_w)
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
    return x_opt, int(stats.get("iter_count", 0)), status, history, message


SOLVERS = {
    "svd": _svd,
    "gauss-newton": _gauss_newton,
    "lm": _levenberg_marquardt,
    "ipopt": _ipopt,
}
