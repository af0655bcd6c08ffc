"""`Problem`: weighted residuals and Jacobians of the deviations of chosen parameters.

The one object every solver, the analysis and the covariance evaluate: the measured
points (and orientations) against a robot's model, through its compiled kernels, with
the evaluations memoised so that the analysis and the solver share them.
"""

from __future__ import annotations

import numpy as np

from ..model import kinematics
from ..model.frames import rotation_vector
from ..model.robot import Robot


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
