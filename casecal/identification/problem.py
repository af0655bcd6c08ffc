"""`Problem`: weighted residuals and Jacobians of the deviations of chosen parameters.

The one object every solver, the analysis and the covariance evaluate: the measured
points (and orientations) against a robot's model, through its compiled kernels. The
Jacobian is never held whole: `Problem.reduced` evaluates it in batches of poses and folds
each into the small R factor of ``[J | r]`` (`casecal.identification.linalg.Reduction`),
so memory stays O(k² + batch) whatever the number of poses. Residuals and reductions are
memoised, so that the analysis, the solver and the covariance share them.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .._threads import thread_map
from ..model import kinematics
from ..model.frames import rotation_vector
from ..model.robot import Robot
from .linalg import Reduction

BATCH_POSES = 4096
"""Poses per batch of `Problem.reduced`: a batch's Jacobian (3 · 4096 × k) stays in cache."""

FOLD_RUNS = 4
"""Runs of batches a pass over the poses (QR or normal equations) evaluates and reduces
independently, as many at once as there are cores."""

MEMO = 5
"""Bytes of evaluations a memo keeps, in units of one evaluation of what is measured (the
points, N · 3m doubles, and with orientations also the poses, N · 16): the fit's start, its
solver's point and trial point, and where it ends, so that the audit finds the start and
the end again. Ten units of the points alone took the same passes over 2e5 positions with
a peak of 19.7 point arrays, where five take 15.5 (4 fewer arrays of 24 MB at 1e6 poses);
four cost a pass more."""

MEMO_SMALL = 64
"""Reductions and normal equations (O(k²) each) a memo keeps."""


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
    memo : dict, optional
        Where evaluations and reductions are memoised, keyed by the whole parameter vector
        and the data arrays' identities: problems of the same data (the same `q`, `y`, `w`
        and `orientations` arrays) share what they evaluate through one, so that a point
        the solver evaluated is not evaluated again by the analysis or the audit.
    """

    def __init__(
        self,
        robot: Robot,
        q,
        y,
        w,
        names,
        kernel_names=None,
        orientations=None,
        w_rot: float = 0.0,
        memo: dict | None = None,
    ):
        self.robot = robot
        self.chain = kinematics.chain(robot.structure)
        n = q.shape[0]
        self.q = q
        self.y = np.asarray(y, dtype=float).reshape(n, -1)  # (N, 3m)
        self.m = self.y.shape[1] // 3
        self.w = w
        # coordinates not measured (σ inf, weight 0): their residual is 0, not the model's
        # distance from a stored 0 (a plane's x and y)
        unmeasured = np.asarray(w) == 0
        self._unmeasured = np.tile(unmeasured, (1, self.m)) if np.any(unmeasured) else None
        self.names = tuple(names)
        kernel_names = tuple(kernel_names or names)
        self.columns = self.chain.columns(self.names)
        self.kernel_columns = self.chain.columns(kernel_names)
        self.take = [kernel_names.index(n) for n in self.names]
        self.p0 = robot.vector()
        self.R = orientations
        self.w_rot = float(w_rot)
        # (N, rows per pose); one point: w itself, not a copy of it per problem
        self.w_rows = np.asarray(w, dtype=float) if self.m == 1 else np.tile(w, (1, self.m))
        if orientations is not None:
            self.w_rows = np.hstack([self.w_rows, np.full((n, 3), self.w_rot)])
        self.w_flat = self.w_rows.ravel()
        self._uniform_of: tuple = (None, None)  # (w_rows, its one weight or None)
        self._rows_of: tuple = (None, 0)  # (w_flat, its non-zero count)
        # keys: (kind, structure, data, p bytes[, kernel columns]); the data part names the
        # arrays (poses for evaluations, all of them and the weights for reductions), so
        # problems of other data never meet in a shared memo; a reweighted copy, its own
        self._memo = {} if memo is None else memo
        self._poses = _identity(q)
        self._weights = (self._poses, _identity(self.y), _identity(w), _identity(orientations))
        self._weights += (self.w_rot,)

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
        other._weights = object()
        return other

    def subset(self, poses) -> Problem:
        """The same robot and parameters, only the measurements of `poses`."""
        return Problem(
            self.robot,
            self.q[poses],
            self.y[poses],
            self.w[poses],
            self.names,
            orientations=None if self.R is None else self.R[poses],
            w_rot=self.w_rot,
        )

    def robot_at(self, x: np.ndarray) -> Robot:
        """The robot whose deviations of `names` from this problem's robot are `x`."""
        return self.robot.with_deviations(
            dict(zip(self.names, np.asarray(x).tolist(), strict=True))
        )

    def model_at(self, q: np.ndarray) -> np.ndarray:
        """The robot's modelled measurements at joint values `q` (n, 3m), at the start."""
        return self.robot.measured_points(q).reshape(len(q), -1)

    def restricted(self, names) -> Problem:
        """The same data and kernel for a subset of the parameters (shares the memo)."""
        other = type(self).__new__(type(self))
        other.__dict__.update(self.__dict__)
        other.names = tuple(names)
        other.columns = self.chain.columns(other.names)
        kernel_names = [self.chain.names[c] for c in self.kernel_columns]
        other.take = [kernel_names.index(n) for n in other.names]
        return other

    def _memoised(self, key, compute):
        # solvers, the identifiability analysis and the result ask for the same points
        value = self._memo.pop(key, None)
        if value is None:
            value = compute()
            self._make_room(value)
        self._memo[key] = value  # the latest used last
        return value

    def _make_room(self, value) -> None:
        """Evict the least recently used entries of `value`'s size (`MEMO`, `MEMO_SMALL`)."""
        if isinstance(value, np.ndarray):
            unit = self.y.nbytes + (0 if self.R is None else 16 * self.y.itemsize * len(self.q))
            budget = MEMO * unit
            large = [(k, v.nbytes) for k, v in self._memo.items() if isinstance(v, np.ndarray)]
            total = value.nbytes + sum(size for _, size in large)
            for key, size in large:
                if total <= budget:
                    break
                del self._memo[key]
                total -= size
        else:
            small = [k for k, v in self._memo.items() if not isinstance(v, np.ndarray)]
            for key in small[: max(len(small) + 1 - MEMO_SMALL, 0)]:
                del self._memo[key]

    def _at(self, p: np.ndarray) -> bytes:
        """What names `p` in memo keys: with the rotations' anchor, `p0`'s pitches and
        yaws (the same `p` from another start is another robot there,
        `casecal.model.kinematics`; elsewhere it is the same robot, so a problem rebuilt
        where a solver ended finds that point's evaluations)."""
        return p.tobytes() + self.p0[self.chain.anchor_index].tobytes()

    def _evaluation_key(self, kind: str, p: np.ndarray) -> tuple:
        return (kind, self.chain.structure, self._poses, self._at(p))

    def _evaluate(self, kind: str, p: np.ndarray) -> np.ndarray:
        key = self._evaluation_key(kind, p)
        return self._memoised(key, lambda: self.chain.evaluate(kind, self.q, p, anchor=self.p0))

    def p(self, x: np.ndarray) -> np.ndarray:
        """The kernels' parameter vector at `x`: ``p0 + x``, the rotations' entries about
        the anchor `p0` (`casecal.model.rotation_chart`, `casecal.model.kinematics`)."""
        p = self.p0.copy()
        p[list(self.columns)] += x
        return p

    def point_residuals(self, x: np.ndarray) -> np.ndarray:
        """Unweighted ``y - f`` of the points, shape (N, m, 3), m; 0 where not measured."""
        f = self._evaluate("points", self.p(x))
        r = self.y - f
        if self._unmeasured is not None:
            r = np.where(self._unmeasured, 0.0, r)
        return r.reshape(len(self.q), self.m, 3)

    def orientation_residuals(self, x: np.ndarray) -> np.ndarray | None:
        """Unweighted ``log(R_meas R_modelᵀ)``, shape (N, 3), rad; None without data."""
        if self.R is None:
            return None
        R_model = self._evaluate("fk", self.p(x))[:, :3, :3]
        return rotation_vector(self.R @ np.swapaxes(R_model, 1, 2))

    def residual(self, x: np.ndarray, ahead: bool = False) -> np.ndarray:
        """Weighted residuals, shape (N · rows per pose,), pose-major.

        `ahead`: a solver's trial point it will likely step from next. Where the points are
        not yet evaluated there, one pass evaluates them with the Jacobian and memoises the
        normal equations too (`reduced(..., exact=False)` then finds them): the cost of a
        Jacobian pass instead of a points pass plus a Jacobian pass.
        """
        key = self._evaluation_key("points", self.p(x))
        if ahead and self.R is None and key not in self._memo:
            self._points_and_normal(x)
        r = self.point_residuals(x).reshape(len(self.q), -1)
        if self.R is not None:
            r = np.hstack([r, self.orientation_residuals(x)])
        return np.multiply(r, self.w_rows, out=r).ravel()  # r is new: no second array

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        """Weighted ``∂f/∂x``, shape (N · rows per pose, k): whole, for small problems and
        tests; the solvers and the analysis use `reduced`."""
        J = self._kernel_rows(self.p(x), slice(None))[0]
        return J[:, self.take] if len(self.take) != J.shape[1] else J

    def reduced(self, x: np.ndarray, r: np.ndarray | None = None, exact=True) -> Reduction:
        """The weighted ``[J | r]`` at `x`, reduced to its R factor batch by batch.

        Parameters
        ----------
        x : ndarray, shape (k,)
        r : ndarray, optional
            `residual` at `x`, when the caller has it.
        exact : bool
            True: Householder QR of the batches, for every judgement (rank, covariance,
            audit). False, for a solver's step: the normal equations ``JᵀJ``, ``Jᵀr``
            accumulated by BLAS-3 (four times faster), where the scaled condition number
            allows (`Reduction.from_normal`), else QR.

        Returns
        -------
        Reduction
            Of the columns `names`, with ``rows`` the N · rows-per-pose residuals.
        """
        p = self.p(x)
        at = ("reduced", self.chain.structure, self._at(p), self._weights)
        whole = self._memo.get((*at, self.kernel_columns)) or self._from_wider(at)
        if whole is None and not exact:
            r = self.residual(x) if r is None else r
            G, g = self._memoised(self._normal_key(p), lambda: self._normal(p, r))
            take = self.take
            step = Reduction.from_normal(G[np.ix_(take, take)], g[take], r @ r, r.size)
            if step is not None:
                return self._observed(step)
        if whole is None:
            whole = self._memoised(
                (*at, self.kernel_columns),
                lambda: self._reduce(p, self.residual(x) if r is None else r),
            )
        whole = self._observed(whole)
        if len(self.take) == whole.k and self.take == list(range(whole.k)):
            return whole
        return whole.columns(self.take)

    @property
    def observed_rows(self) -> int:
        """Rows of non-zero weight: the observations (a pose a robust loss left out and a
        coordinate not measured are none). Counted once per weights: a pass over N rows."""
        if self._rows_of[0] is not self.w_flat:
            self._rows_of = (self.w_flat, int(np.count_nonzero(self.w_flat)))
        return self._rows_of[1]

    def _observed(self, linear: Reduction) -> Reduction:
        """`linear` counting only rows of non-zero weight (`observed_rows`): a pose left out
        would inflate the degrees of freedom."""
        rows = self.observed_rows
        return linear if rows == linear.rows else dataclasses.replace(linear, rows=rows)

    def _from_wider(self, at: tuple) -> Reduction | None:
        """A memoised reduction at the same point whose kernel covers this one's columns."""
        need = self.kernel_columns
        for key, value in self._memo.items():
            if key[:4] == at and set(need) <= set(key[4]):
                return value.columns([key[4].index(c) for c in need])
        return None

    def with_kernel(self, kernel_names) -> Problem:
        """The same problem evaluating the columns `kernel_names` (a superset of `names`),
        sharing the memo: a reduction of wider columns serves it without a new pass."""
        other = self.restricted(self.names)
        other.kernel_columns = self.chain.columns(tuple(kernel_names))
        kernel = [self.chain.names[c] for c in other.kernel_columns]
        other.take = [kernel.index(n) for n in other.names]
        return other

    def _normal_key(self, p: np.ndarray) -> tuple:
        return ("normal", self.chain.structure, self._at(p), self._weights, self.kernel_columns)

    def _cuts(self) -> tuple[list[slice], list[slice], tuple[int, int, int]]:
        """The batches' slices of the poses and of the residual vector, and the shape of a
        buffer for one batch's kernel output."""
        n, per_pose = len(self.q), self.w_rows.shape[1]
        cuts = np.array_split(np.arange(n), max(n // BATCH_POSES, 1))
        batches = [slice(c[0], c[-1] + 1) for c in cuts]
        rows = [slice(b.start * per_pose, b.stop * per_pose) for b in batches]
        width = len(self.kernel_columns) + (self.R is None)  # the points' column
        return batches, rows, (len(cuts[0]), per_pose, width)  # the first is the largest

    def _runs(self, p: np.ndarray, each) -> list:
        """``each(batches)`` for `FOLD_RUNS` runs of consecutive batches of poses at `p`,
        in threads (as many at once as there are cores), in order of the runs.

        `batches` yields ``(J, f, poses, rows)`` per batch of the run: the Jacobian rows
        (weighted, or unweighted where every row has the weight `_uniform`), the points
        (None with orientations) and the batch's slices of the poses and of the residual
        vector, evaluated in the run's thread into one reused buffer (valid until the next
        is asked for). Each run's arithmetic, and the
        caller's combination of the runs in order, is the same whatever the core count.
        """
        batches, rows, shape = self._cuts()

        def run(indices):
            buffer = np.empty(shape)
            return each(
                (*self._kernel_rows(p, batches[i], buffer, weigh=False), batches[i], rows[i])
                for i in indices
            )

        runs = [run for run in np.array_split(np.arange(len(batches)), FOLD_RUNS) if run.size]
        return thread_map(run, runs)

    def _reduce(self, p: np.ndarray, r: np.ndarray) -> Reduction:
        """The R factor of ``[J | r]`` at `p`, the runs' reductions merged in order."""
        k = len(self.kernel_columns)
        whole, *rest = self._runs(
            p, lambda batches: Reduction.folded(k, ((J, r[rows]) for J, _, _, rows in batches))
        )
        for part in rest:
            whole = whole.merge(part)
        if self._uniform is None:
            return whole
        # R of [c J | r] is R of [J | r] with its J columns times c: a memory pass saved
        return dataclasses.replace(whole, R=whole.R * self._uniform)

    def _normal(self, p: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(JᵀJ, Jᵀr)`` of every kernel column, (k, k) and (k,)."""

        def residual(J, f, poses, rows):
            return r[rows]

        return self._weighed(_summed(self._runs(p, lambda batches: self._gram(batches, residual))))

    def _weighed(self, normal: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """``(JᵀJ, Jᵀr)`` of the weighted J from the runs' sums, which are of the unweighted
        J where the weights are one number c (`_kernel_rows`): ``(c² G, c g)``."""
        G, g = normal
        c = self._uniform
        return (G, g) if c is None else (G * (c * c), g * c)

    def _gram(self, batches, residual) -> tuple[np.ndarray, np.ndarray]:
        """``(JᵀJ, Jᵀr)`` of one run's `batches`; ``residual(J, f, poses, rows)`` gives
        each batch's weighted residuals."""
        k = len(self.kernel_columns)
        G, g = np.zeros((k, k)), np.zeros(k)
        for batch in batches:
            J = batch[0]
            G += J.T @ J
            g += J.T @ residual(*batch)
        return G, g

    def _points_and_normal(self, x: np.ndarray) -> None:
        """Memoise the points at `x` and the normal equations there, from one pass."""
        p = self.p(x)
        f = np.empty_like(self.y)  # (N, 3m); each run writes its own poses

        def residual(J, f_batch, poses, rows):
            f[poses] = f_batch
            # as `residual` forms it, bit for bit
            return ((self.y[poses] - f_batch) * self.w_rows[poses]).ravel()

        G, g = self._weighed(_summed(self._runs(p, lambda batches: self._gram(batches, residual))))
        self._memoised(self._evaluation_key("points", p), lambda: f)
        self._memoised(self._normal_key(p), lambda: (G, g))

    def _kernel_rows(self, p: np.ndarray, poses: slice, buffer=None, weigh: bool = True):
        """Weighted Jacobian rows of `poses`, every kernel column, (rows, k_kernel), and
        the unweighted points (n, 3m) (None with orientations), from one evaluation.

        Written into `buffer` (C-ordered, (n ≥ poses, rows per pose, k_kernel + 1), or
        k_kernel with orientations) if given. `weigh` False: where every row has the one
        weight `_uniform`, the rows are left unweighted (the caller scales what it sums:
        a pass over the rows saved).
        """
        q, k = self.q[poses], len(self.kernel_columns)
        out = None if buffer is None else buffer[: len(q)]
        if self.R is None:
            both = self.chain.evaluate(
                "points_and_jacobian", q, p, self.kernel_columns, out, anchor=self.p0
            )
            J, f = both[:, :, :k], both[:, :, k]
        else:  # rotation rows under the points' rows
            J = self.chain.evaluate("points_jacobian", q, p, self.kernel_columns, anchor=self.p0)
            rot = self.chain.evaluate("pose_jacobian", q, p, self.kernel_columns, anchor=self.p0)[
                :, 3:, :
            ]  # J: (n, 3m, k)
            J, f = np.concatenate([J, rot], axis=1, out=out), None
        self._weigh(J, poses, weigh)  # J is this call's own (or the caller's buffer)
        return J.reshape(-1, k), f

    @property
    def _uniform(self) -> float | None:
        """The one weight of every row (one σ for all), or None (`_kernel_rows`)."""
        rows, weight = self._uniform_of
        if rows is not self.w_rows:  # weights set anew (a subclass's, a reweighted copy)
            weight = _uniform(self.w_rows)
            self._uniform_of = (self.w_rows, weight)
        return weight

    def _weigh(self, J: np.ndarray, poses: slice, weigh: bool = True) -> None:
        """Multiply Jacobian rows (n, rows per pose, k) of `poses` by their weights in
        place, unless `weigh` is False and they share one (`_kernel_rows`)."""
        if weigh or self._uniform is None:
            J *= self.w_rows[poses, :, None]


def _summed(parts: list[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    """The runs' ``(G, g)`` added in order."""
    G, g = parts[0]
    for G_part, g_part in parts[1:]:
        G, g = G + G_part, g + g_part
    return G, g


def _uniform(w_rows: np.ndarray) -> float | None:
    """The one weight of every row, if they share one (one σ for all), else None."""
    c = w_rows.flat[0] if w_rows.size else 0.0
    return float(c) if c > 0 and np.all(w_rows == c) else None


def _identity(a) -> tuple | None:
    """What names an array in memo keys: its memory, shape, strides and type (None: None).
    Arrays of one `identify` live as long as its memo, so the address is not reused."""
    if a is None:
        return None
    a = np.asarray(a)
    return (a.__array_interface__["data"][0], a.shape, a.strides, a.dtype.str)
