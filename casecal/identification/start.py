"""Where a fit starts, and the frame it works in.

Real measurements come in an instrument's frame: a laser tracker metres away, turned by any
angle, sometimes pitched 90° (a robot on a wall, a tracker standing upright). Linearising
at the nominal base would start far outside the region where Gauss-Newton converges, and
roll-pitch-yaw angles lose a degree of freedom at ±90° pitch (gimbal lock), where the
base's rx and rz columns become parallel. So when the whole base frame is identified and
the noise is the same on every axis, the fit works in a frame moved by a rigid fit of the
nominal positions to the measured ones (`casecal.model.frames.rigid_fit`): there the base
starts at its nominal value, a small correction away from the truth, far from any gimbal
lock; the result is mapped back into the instrument's frame at the end, with its
covariance.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..model.frames import matrix_from_rpy, rigid_fit, rpy_from_matrix
from ..model.parameters import frame_names
from ..model.robot import Frame, Robot
from ..model.rotation_chart import deviate, deviation

BASE = frame_names("base")


@dataclass(frozen=True)
class FitFrame:
    """A rigid transform ``G = (R, t)`` from the fit's frame to the instrument's.

    Attributes
    ----------
    R : ndarray, shape (3, 3)
    t : ndarray, shape (3,)
        m.
    """

    R: np.ndarray
    t: np.ndarray

    @classmethod
    def identity(cls) -> FitFrame:
        return cls(np.eye(3), np.zeros(3))

    @property
    def is_identity(self) -> bool:
        return bool(np.array_equal(self.R, np.eye(3)) and not self.t.any())

    def points_in(self, y: np.ndarray) -> np.ndarray:
        """Instrument-frame points (..., 3) expressed in the fit frame, m (`y` itself in
        the identity frame: no copy of a million points)."""
        return y if self.is_identity else (y - self.t) @ self.R

    def rotations_in(self, R_meas: np.ndarray | None) -> np.ndarray | None:
        """Measured rotations (N, 3, 3) expressed in the fit frame."""
        return None if R_meas is None else self.R.T @ R_meas

    def vectors_out(self, v: np.ndarray | None) -> np.ndarray | None:
        """Fit-frame vectors (residuals, rotation vectors) (..., 3) in the instrument frame
        (`v` itself in the identity frame: a million residuals are not copied)."""
        if v is None or self.is_identity:
            return v
        return v @ self.R.T

    def base_out(self, base: Frame) -> Frame:
        """A fit-frame base frame expressed in the instrument frame."""
        return Frame(*_xyz_rpy(self._out_matrix(np.array([*base.xyz, *base.rpy]))))

    def _out_matrix(self, values: np.ndarray) -> np.ndarray:
        T = np.eye(4)
        T[:3, :3] = self.R @ matrix_from_rpy(values[3:])
        T[:3, 3] = self.R @ values[:3] + self.t
        return T

    def robot_out(self, robot: Robot) -> Robot:
        """`robot` (fitted in this frame) with its base in the instrument frame."""
        if self.is_identity:
            return robot
        return dataclasses.replace(robot, base=self.base_out(robot.base), auto_beta=False)

    def covariance_out(
        self, cov: np.ndarray, estimated, robot: Robot, nominal_rpy=None
    ) -> np.ndarray:
        """`cov` of `estimated` (fit frame, at `robot`) with base entries mapped out.

        The map from fit-frame to instrument-frame base deviations is linearised by
        central differences; held base parameters are constants of the map. Rotations
        deviate by a turn (`casecal.model.rotation_chart`): in the fit frame about
        `robot`'s base, as the fit's covariance is; out, about `nominal_rpy` (default: the
        mapped base's own), as the reported deviations are.
        """
        idx = [k for k, n in enumerate(estimated) if n in BASE]
        if self.is_identity or not idx:
            return cov
        at = np.array([*robot.base.xyz, *robot.base.rpy])
        anchor = _xyz_rpy_vector(self._out_matrix(at))[3:] if nominal_rpy is None else nominal_rpy
        slots = [BASE.index(estimated[k]) for k in idx]
        M = np.eye(len(estimated))
        h = 1e-6
        for col, slot in zip(idx, slots, strict=True):
            up, down = (_xyz_rpy_vector(self._out_matrix(_stepped(at, slot, s))) for s in (h, -h))
            diff = up - down
            diff[3:] = np.subtract(deviation(anchor, up[3:]), deviation(anchor, down[3:]))
            diff[3:] = (diff[3:] + np.pi) % (2 * np.pi) - np.pi  # angles wrap at ±π
            M[np.ix_(idx, [col])] = (diff[slots] / (2 * h))[:, None]
        return M @ cov @ M.T


def _stepped(at: np.ndarray, slot: int, h: float) -> np.ndarray:
    """Base values `at` (xyz, rpy) deviated by `h` in `slot` (0-5), rotations by a turn."""
    out = at.copy()
    if slot < 3:
        out[slot] += h
    else:
        out[3:] = deviate(at[3:], np.eye(3)[slot - 3] * h)
    return out


def _xyz_rpy(T: np.ndarray) -> tuple[tuple[float, ...], tuple[float, ...]]:
    return tuple(T[:3, 3].tolist()), tuple(rpy_from_matrix(T[:3, :3]))


def _xyz_rpy_vector(T: np.ndarray) -> np.ndarray:
    xyz, rpy = _xyz_rpy(T)
    return np.array([*xyz, *rpy])


def choose_frame(robot: Robot, q, y, sigma, names, weights) -> tuple[FitFrame, str]:
    """The fit frame for these data (identity unless the whole base is identified).

    Parameters
    ----------
    robot : Robot
        Nominal robot (its measured points, when it has any, define the model points).
    q : ndarray, shape (N, dof)
    y : ndarray, shape (N, m, 3)
        Measured points in the instrument frame, m.
    sigma : ndarray, shape (N, 3)
    names : sequence of str
        Parameters to identify.
    weights : ndarray, shape (N,)
        Weight of each pose's points in the rigid fit.

    Returns
    -------
    frame : FitFrame
    note : str
        One sentence for the summary, empty when the frame is the identity.
    """
    if not set(BASE) <= set(names) or not np.all(sigma == sigma[:, :1]):
        return FitFrame.identity(), ""
    model = robot.measured_points(q).reshape(-1, 3)
    R, t = rigid_fit(model, y.reshape(-1, 3), weights=np.repeat(weights, y.shape[1]))
    frame = FitFrame(R, t)
    moved = np.linalg.norm(t)
    angle = np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1.0, 1.0)))
    return frame, (
        f"The measured points were brought near the robot by a rigid fit of the nominal "
        f"positions to them ({moved * 1e3:.1f} mm and {angle:.2f}° from the nominal base); "
        "the fit ran in that frame and the base frame was mapped back."
    )


def partial_base_start(robot: Robot, problem_at, names) -> tuple[Robot, str]:
    """Start for a fit of some, not all, base parameters: the rigid fit's values for them.

    Used when `choose_frame` cannot move the data (anisotropic noise, or only part of the
    base asked for); kept only if it lowers the residual.
    """
    base = [n for n in names if n in BASE]
    if not base:
        return robot, ""
    probe = problem_at(robot, base)
    y, q, w = probe.y.reshape(-1, 3), probe.q, probe.w
    model = robot.measured_points(q).reshape(-1, 3)
    R, t = rigid_fit(model, y, weights=np.repeat(np.mean(w**2, axis=1), probe.m))
    fit = np.eye(4)
    fit[:3, :3], fit[:3, 3] = R, t
    values = dict(zip(BASE, _xyz_rpy_vector(fit @ robot.base.matrix()).tolist(), strict=True))
    start = robot.with_parameters({n: values[n] for n in base})
    before = np.sum(probe.residual(np.zeros(len(base))) ** 2)
    after = np.sum(problem_at(start, base).residual(np.zeros(len(base))) ** 2)
    if not after < before:
        return robot, ""
    return start, (
        f"The asked-for base parameters ({', '.join(base)}) started from a rigid fit of the "
        "nominal positions to the measured ones."
    )
