"""`PixelProblem`: a camera's pixels as the residuals of the one fitting path.

A `Problem` whose measured "points" are the board's corners as the camera sees them. Each
corner's pixel residual (u, v) is turned into a length at the board's distance, the
object-space error::

    r_u = (u_meas − û) · Z_i / fx,   r_v = (v_meas − v̂) · Z_i / fy      (m)

with Z_i the board's mean depth in view i and fx, fy the focal lengths, both at the
nominal camera and held for the whole fit; the third coordinate is not measured (weight
0, as a plane's x and y). The weights ``fx / (Z_i σ_px)`` make every weighted residual
exactly the pixel residual over σ_px, so the fit is the pixels' least squares; the
lengths let the rounds, the audit and the summary speak metres, and compare a parameter's
effect on the robot's positions with what the camera resolves (σ_px · Z / f).

The robot is the rig of `casecal.observations.rig` (its base and tool frames are the
camera's and the board's poses; the intrinsics are its ``camera_*`` parameters). The
Jacobian is exact: the rig's frame Jacobian (position and the rotation δφ, ``δR = [δφ]×
R``) through the rigid chain to the corners and the projection's derivatives
(`casecal.observations.camera`), as in `casecal.observations.residuals`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import CalibrationError
from ..observations.camera import (
    INTRINSIC_NAMES,
    Intrinsics,
    jacobian_intrinsics,
    jacobian_point,
    project,
)
from ..observations.residuals import skew
from ..observations.rig import INTRINSIC_PARAMETERS
from .problem import Problem

OUT_OF_VIEW = 1e6
"""Object-space value (m) of every corner where the parameters are no camera's."""


@dataclass(frozen=True, eq=False)
class View:
    """What a `PixelProblem` needs besides a `Problem`'s arrays.

    Attributes
    ----------
    mode : {"eye_in_hand", "eye_to_hand"}
    corners : ndarray, shape (c, 3)
        The board's corners in the board's frame, m.
    scale : ndarray, shape (N, 2)
        Metres per pixel of u and v per view (``Z_i / fx``, ``Z_i / fy``).
    found : ndarray, shape (N, c), bool
        Corners the detector found.
    """

    mode: str
    corners: np.ndarray
    scale: np.ndarray
    found: np.ndarray

    def subset(self, poses) -> View:
        return View(self.mode, self.corners, self.scale[poses], self.found[poses])


class PixelProblem(Problem):
    """Weighted object-space pixel residuals and their Jacobian (module doc).

    Parameters
    ----------
    robot : Robot
        A rig (`casecal.observations.rig.rig_robot`).
    q : ndarray, shape (N, dof)
    y : ndarray, shape (N, c, 3)
        Measured pixels in object space: ``(u · scale_u, v · scale_v, 0)``, m; 0 where a
        corner was not found.
    w : ndarray, shape (N, 3)
        ``(1 / (σ scale_u), 1 / (σ scale_v), 0)`` per view.
    names, kernel_names, memo
        As `Problem`'s.
    view : View
    """

    def __init__(self, robot, q, y, w, names, kernel_names=None, memo=None, *, view: View):
        super().__init__(robot, q, y, w, names, kernel_names, memo=memo)
        self.view = view
        self._intrinsics = [self.chain.index[n] for n in INTRINSIC_PARAMETERS]
        lost = ~view.found
        if lost.any():  # a corner not found: none of its rows is an observation
            rows = np.repeat(lost, 3, axis=1)
            self._unmeasured = self._unmeasured | rows
            self.w_rows = np.where(rows, 0.0, self.w_rows)
            self.w_flat = self.w_rows.ravel()

    def subset(self, poses) -> PixelProblem:
        """The same rig and parameters, only the views `poses`."""
        return PixelProblem(
            self.robot,
            self.q[poses],
            self.y.reshape(len(self.q), -1, 3)[poses],
            self.w[poses],
            self.names,
            view=self.view.subset(poses),
        )

    def model_at(self, q: np.ndarray) -> np.ndarray:
        """The modelled object-space pixels at joint values `q` (n, 3c), at the start."""
        n = len(q)
        scale = np.broadcast_to(self.view.scale.mean(axis=0), (n, 2))
        return self._model(q, self.p0, None, scale)

    def _evaluate(self, kind: str, p: np.ndarray) -> np.ndarray:
        if kind != "points":
            raise ValueError(f"a camera's problem evaluates points only, not {kind!r}")
        key = self._evaluation_key(kind, p)
        return self._memoised(key, lambda: self._model(self.q, p, None, self.view.scale))

    def _kernel_rows(self, p: np.ndarray, poses: slice, buffer=None, weigh: bool = True):
        f, J = self._model(self.q[poses], p, self.kernel_columns, self.view.scale[poses])
        self._weigh(J, poses, weigh)
        return J.reshape(-1, J.shape[-1]), f

    def _model(self, q, p, columns, scale):
        """Object-space pixels (n, 3c) and, with `columns`, their Jacobian (n, 3c, k)."""
        n, c = len(q), len(self.view.corners)
        T = self.chain.evaluate("fk", q, p, anchor=self.p0)
        R, t = T[:, :3, :3], T[:, :3, 3]
        corners = self.view.corners
        if self.view.mode == "eye_to_hand":  # p = R c + t
            a = np.einsum("nij,mj->nmi", R, corners)
            p_cam = a + t[:, None]
        else:  # p = Rᵀ (c − t)
            w = corners[None] - t[:, None]
            p_cam = np.einsum("nji,nmj->nmi", R, w)
        intr = _intrinsics(p[self._intrinsics])
        flat = p_cam.reshape(-1, 3)
        if intr is None or not np.all(flat[:, 2] > 0):
            # a trial step past what a camera can be (a focal length ≤ 0, the board behind
            # the camera): a cost no solver accepts, so that it shortens the step
            f = np.full((n, 3 * c), OUT_OF_VIEW)
            return f if columns is None else (f, np.zeros((n, 3 * c, len(columns))))
        f = np.zeros((n, c, 3))
        f[..., :2] = project(intr, flat).reshape(n, c, 2) * scale[:, None, :]
        if columns is None:
            return f.reshape(n, 3 * c)
        k = len(columns)
        J6 = self.chain.evaluate("pose_jacobian", q, p, columns, anchor=self.p0)
        dpos, drot = J6[:, None, :3], J6[:, None, 3:]  # (n, 1, 3, k)
        if self.view.mode == "eye_to_hand":  # δp = δt − [a]× δφ
            dp = dpos - skew(a) @ drot
        else:  # δp = Rᵀ ([w]× δφ − δt)
            dp = np.einsum("nji,nmjk->nmik", R, skew(w) @ drot - dpos)
        J = np.zeros((n, c, 3, k))
        J[:, :, :2] = jacobian_point(intr, flat).reshape(n, c, 2, 3) @ dp
        lens = _lens_columns(columns, self._intrinsics)
        if lens:
            Jl = jacobian_intrinsics(intr, flat).reshape(n, c, 2, len(INTRINSIC_NAMES))
            for i, j in lens:
                J[:, :, :2, i] = Jl[..., j]
        J[:, :, :2] *= scale[:, None, :, None]
        return f.reshape(n, 3 * c), J.reshape(n, 3 * c, k)


def _lens_columns(columns, intrinsics) -> list[tuple[int, int]]:
    """(position in `columns`, index in `INTRINSIC_NAMES`) of the intrinsics' kernel
    columns `intrinsics` among `columns`."""
    where = {col: j for j, col in enumerate(intrinsics)}
    return [(i, where[col]) for i, col in enumerate(columns) if col in where]


def _intrinsics(values: np.ndarray) -> Intrinsics | None:
    """The intrinsics `values` stand for, or None where they are no camera's."""
    try:
        return Intrinsics.from_vector(values)
    except CalibrationError:
        return None
