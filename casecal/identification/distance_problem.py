"""`DistanceProblem`: distances between two poses' tool points as rows of the one fit.

A `Problem` whose "poses" are the measured pairs and whose one "point" per pair is the
distance residual in its first coordinate, the other two not measured (weight 0, as a
plane's x and y)::

    r_k = (d_k − |f(q_i) − f(q_j)|) / σ_k,     ∂r_k/∂x = −u_kᵀ (J_i − J_j) / σ_k

with f the tool point (`casecal.Robot.position`), u_k the unit vector from one point to
the other and J the tool point's exact Jacobian in the deviations. So the rounds, the
noise-aware rank, the solvers and the covariance are the ones every fit runs
(`casecal.identification.rounds`); `casecal.identification.distances` adds what only
distances need (their mirror images, their blind directions over pairs).
"""

from __future__ import annotations

import numpy as np

from .problem import Problem, _identity


class DistanceProblem(Problem):
    """Weighted distance residuals and their Jacobian (module doc).

    Parameters
    ----------
    robot : Robot
    q : ndarray, shape (P, dof)
        The first pose of each pair (what the fit's pose-wise judgements look at).
    y : ndarray, shape (P, 1, 3)
        ``(d_k, 0, 0)``: the measured distances, m.
    w : ndarray, shape (P, 3)
        ``(1 / σ_k, 0, 0)``.
    names, kernel_names, memo
        As `Problem`'s.
    poses : ndarray, shape (N, dof)
        The measured poses, each evaluated once however many pairs it is in.
    pairs : ndarray of int, shape (P, 2)
        Rows of `poses` of each pair.
    """

    def __init__(self, robot, q, y, w, names, kernel_names=None, memo=None, *, poses, pairs):
        super().__init__(robot, q, y, w, names, kernel_names, memo=memo)
        self.poses, self.pairs = poses, np.asarray(pairs)
        # the pairs, not only their first poses, name the data in memo keys
        self._poses = (self._poses, _identity(poses), _identity(self.pairs))
        self._weights = (self._poses, *self._weights[1:])

    def subset(self, rows) -> DistanceProblem:
        """The same robot and parameters, only the pairs `rows`."""
        return DistanceProblem(
            self.robot,
            self.q[rows],
            self.y.reshape(len(self.q), 1, 3)[rows],
            self.w[rows],
            self.names,
            poses=self.poses,
            pairs=self.pairs[rows],
        )

    def model_at(self, q: np.ndarray) -> np.ndarray:
        """The modelled distances (n, 3) from poses `q`, in place of the first pose of the
        first n pairs, to those pairs' second poses."""
        n = len(q)
        both = np.vstack([q, self.poses[self.pairs[:n, 1]]])
        return self._distances(both, np.arange(n), np.arange(n, 2 * n), self.p0, None)[0]

    def _evaluate(self, kind: str, p: np.ndarray) -> np.ndarray:
        if kind != "points":
            raise ValueError(f"a distance problem evaluates distances only, not {kind!r}")
        key = self._evaluation_key(kind, p)
        return self._memoised(key, lambda: self._model(slice(None), p, None)[0])

    def _kernel_rows(self, p: np.ndarray, poses: slice, buffer=None, weigh: bool = True):
        f, J = self._model(poses, p, self.kernel_columns)
        self._weigh(J, poses, weigh)
        return J.reshape(-1, J.shape[-1]), f

    def _model(self, rows, p, columns):
        """Distances of the pairs `rows` and, with `columns`, their Jacobian."""
        used, at = np.unique(self.pairs[rows], return_inverse=True)
        at = at.reshape(-1, 2)
        return self._distances(self.poses[used], at[:, 0], at[:, 1], p, columns)

    def _distances(self, q, first, second, p, columns):
        """Distances (n, 3) as ``(d, 0, 0)`` between the tool points of poses ``q[first]``
        and ``q[second]`` and, with `columns`, their Jacobian (n, 3, k); else None."""
        n = len(first)
        points = self.chain.evaluate("position", q, p, anchor=self.p0)
        v = points[first] - points[second]
        d = np.linalg.norm(v, axis=1)
        f = np.zeros((n, 3))
        f[:, 0] = d
        if columns is None:
            return f, None
        J = self.chain.evaluate("position_jacobian", q, p, columns, anchor=self.p0)
        u = v / np.maximum(d, 1e-300)[:, None]
        out = np.zeros((n, 3, len(columns)))
        out[:, 0] = np.einsum("pi,pik->pk", u, J[first] - J[second])
        return f, out
