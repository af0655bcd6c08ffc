"""The camera: OpenCV's pinhole model with Brown–Conrady distortion, and its exact derivatives.

Model (OpenCV's ``projectPoints`` with the five coefficients k1 k2 p1 p2 k3), for a point
``p = (x, y, z)`` in the camera frame (m, z along the optical axis, x right, y down)::

    x' = x / z,  y' = y / z,  r² = x'² + y'²
    radial = 1 + k1 r² + k2 r⁴ + k3 r⁶
    x'' = x' radial + 2 p1 x' y' + p2 (r² + 2 x'²)
    y'' = y' radial + p1 (r² + 2 y'²) + 2 p2 x' y'
    u = fx x'' + cx,  v = fy y'' + cy                    (pixels)

Points with z ≤ 0 are behind the camera: `project` refuses them (the formulas would give a
pixel for them, a wrong one). OpenCV's rational (k4 k5 k6), thin-prism (s1..s4) and tilt
(τx τy) terms are not supported: `Intrinsics.from_opencv` refuses them when non-zero.

Why numpy and not CasADi: the projection is a closed form of a few products, evaluated per
corner; its derivatives here are exact (hand-derived, checked against OpenCV's own Jacobian
and central differences). The robot's CasADi graph already returns the exact pose Jacobian
(`casecal.Robot.pose_jacobian`), so the pixel Jacobian is a chain rule of two small dense
factors per corner, batched in numpy over views × corners (`casecal.observations.residuals`).
Putting π inside the kinematic graph would recompile the robot's kernels for every camera
model and gain nothing in exactness.

Design note: how the pixel block plugs into the fitting path
------------------------------------------------------------
One corner c (board frame, m) seen in view i gives two residuals::

    r = (u_meas − π(K, T_cam←target(q_i, θ) · c)) / σ_px

- eye-to-hand (camera fixed, board on the flange)::

      T_cam←target = T_cam←base · T_base←tool(q, θ) · T_tool←target

  the camera's extrinsics are the base frame seen from the camera (inverse of the camera's
  pose in the base frame, which is what the API takes), the target's pose is in the tool
  frame;
- eye-in-hand (camera on the flange, board fixed)::

      T_cam←target = T_cam←tool · T_tool←base(q, θ) · T_base←target

  with the hand-eye transform T_tool←cam (the API takes it) and the board's pose in the base
  frame.

Jacobians by the chain rule ``∂r/∂θ = −(1/σ) ∂π/∂p · ∂p/∂θ``: ∂π/∂p from `jacobian_point`,
∂p/∂θ from the robot's pose Jacobian (rows δposition and δφ in the base frame) and the rigid
transforms around it; the hand-eye and target poses and the intrinsics (`jacobian_intrinsics`)
add their own columns.

What a planar target cannot see, and what that means for a fit:

- scale: a board at distance z seen with focal length f gives the same image as one at 2z
  with 2f, up to perspective terms of the board's own depth; fx, fy and the distance along
  the optical axis separate only through views at several distances and tilts (a fronto-
  parallel board at one distance leaves f and z in one combination). With intrinsics known
  the board's known spacing fixes the scale.
- cx, cy against the camera's rotation about x and y: a shift of the principal point looks
  like a small pan/tilt of the camera for a distant board; tilted views separate them.
- the board's symmetry: a corner detector returns the corners in an order fixed only up to
  the board's symmetry. With rows + cols even (e.g. 7 × 9 inner corners) the colouring is
  unchanged by a 180° turn about the board's z axis, so the detector may return the order
  reversed; with rows == cols, 90° turns too. The fit must resolve the order per view
  (e.g. pick the labelling nearest the nominal prediction) or use a board with rows + cols
  odd (`casecal.observations.target.Checkerboard.symmetric`).
- eye-in-hand: the board's pose in the base and the robot's base frame enter only as their
  product (one rigid transform), likewise the hand-eye transform and the tool frame; the
  identification's base-parameter reduction must treat them as one (as it does base and
  tool frames for a tracker).
"""

from __future__ import annotations

import math
from dataclasses import astuple, dataclass, fields

import numpy as np

from ..errors import CalibrationError

INTRINSIC_NAMES = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")
"""The nine intrinsic parameters, in the column order of `jacobian_intrinsics` (OpenCV's:
focal, principal point, then the distortion coefficients as in its ``distCoeffs``)."""


@dataclass(frozen=True)
class Intrinsics:
    """A pinhole camera with Brown–Conrady distortion, OpenCV's conventions.

    Attributes
    ----------
    fx, fy : float
        Focal lengths, pixels; > 0.
    cx, cy : float
        Principal point, pixels (origin at the centre of the top-left pixel, as OpenCV).
    k1, k2, k3 : float
        Radial distortion coefficients (dimensionless, of r², r⁴, r⁶).
    p1, p2 : float
        Tangential distortion coefficients (dimensionless).
    """

    fx: float
    fy: float
    cx: float
    cy: float
    k1: float = 0.0
    k2: float = 0.0
    p1: float = 0.0
    p2: float = 0.0
    k3: float = 0.0

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            try:
                value = float(value)
            except (TypeError, ValueError):
                raise CalibrationError(
                    f"Intrinsics: {f.name} = {value!r} is not a number; give it in pixels "
                    "(fx fy cx cy) or as a dimensionless coefficient (k1 k2 p1 p2 k3)"
                ) from None
            if not math.isfinite(value):
                raise CalibrationError(
                    f"Intrinsics: {f.name} = {value} is not finite; give a finite value"
                )
            object.__setattr__(self, f.name, value)
        for name in ("fx", "fy"):
            if getattr(self, name) <= 0:
                raise CalibrationError(
                    f"Intrinsics: {name} = {getattr(self, name)} px must be > 0 (a focal "
                    "length in pixels); a mirrored image axis is not supported"
                )

    def vector(self) -> np.ndarray:
        """The nine values in `INTRINSIC_NAMES` order, shape (9,)."""
        return np.array(astuple(self), dtype=float)

    @classmethod
    def from_vector(cls, values) -> Intrinsics:
        """From nine values in `INTRINSIC_NAMES` order."""
        values = np.asarray(values, dtype=float).ravel()
        if values.size != 9:
            raise CalibrationError(
                f"Intrinsics.from_vector: {values.size} values; give nine, in the order "
                f"{', '.join(INTRINSIC_NAMES)}"
            )
        return cls(*values.tolist())

    @classmethod
    def from_opencv(cls, K, dist=None) -> Intrinsics:
        """From OpenCV's camera matrix and distortion coefficients.

        Parameters
        ----------
        K : array-like, shape (3, 3)
            ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]``, pixels. A skew ``K[0, 1]`` ≠ 0 is
            refused (OpenCV's own calibration never estimates one).
        dist : array-like, shape (4,), (5,), (8,), (12,) or (14,), or None
            ``(k1, k2, p1, p2[, k3[, k4, k5, k6[, s1..s4[, τx, τy]]]])``; the terms after k3
            must be zero (not supported). None: no distortion.
        """
        K = np.asarray(K, dtype=float)
        if K.shape != (3, 3):
            raise CalibrationError(
                f"Intrinsics.from_opencv: camera matrix of shape {K.shape}; give the 3 × 3 "
                "matrix [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]"
            )
        if not np.all(np.isfinite(K)):
            raise CalibrationError("Intrinsics.from_opencv: the camera matrix is not finite")
        expected = np.array([[K[0, 0], 0, K[0, 2]], [0, K[1, 1], K[1, 2]], [0, 0, 1]])
        if not np.array_equal(K, expected):
            raise CalibrationError(
                "Intrinsics.from_opencv: the camera matrix is not of the form "
                "[[fx, 0, cx], [0, fy, cy], [0, 0, 1]] (skew or a scaled last row?); "
                f"got {K.tolist()}"
            )
        d = np.zeros(5) if dist is None else np.asarray(dist, dtype=float).ravel()
        if d.size not in (4, 5, 8, 12, 14):
            raise CalibrationError(
                f"Intrinsics.from_opencv: {d.size} distortion coefficients; OpenCV's have "
                "4, 5, 8, 12 or 14 (k1, k2, p1, p2[, k3[, ...]])"
            )
        if d.size > 5 and np.any(d[5:] != 0):
            raise CalibrationError(
                "Intrinsics.from_opencv: the rational, thin-prism or tilt coefficients "
                f"(after k3) are {d[5:].tolist()}; only k1 k2 p1 p2 k3 are supported — "
                "calibrate the camera without CALIB_RATIONAL_MODEL, CALIB_THIN_PRISM_MODEL "
                "and CALIB_TILTED_MODEL"
            )
        k3 = d[4] if d.size >= 5 else 0.0
        return cls(K[0, 0], K[1, 1], K[0, 2], K[1, 2], d[0], d[1], d[2], d[3], k3)

    def to_opencv(self) -> tuple[np.ndarray, np.ndarray]:
        """OpenCV's camera matrix (3, 3) and distortion coefficients (5,): k1 k2 p1 p2 k3."""
        K = np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])
        return K, np.array([self.k1, self.k2, self.p1, self.p2, self.k3])


def _points(p_cam, caller: str) -> np.ndarray:
    """`p_cam` as an (N, 3) float array, refused when a point is not in front of the camera."""
    p = np.asarray(p_cam, dtype=float)
    if p.ndim != 2 or p.shape[1] != 3:
        raise CalibrationError(
            f"{caller}: points of shape {p.shape}; give an (N, 3) array in the camera frame, m"
        )
    if not np.all(np.isfinite(p)):
        raise CalibrationError(f"{caller}: some points are not finite (NaN or inf)")
    behind = np.flatnonzero(~(p[:, 2] > 0))
    if behind.size:
        raise CalibrationError(
            f"{caller}: {behind.size} of {len(p)} points are not in front of the camera "
            f"(z ≤ 0; first at index {behind[:5].tolist()}); a camera cannot see them — "
            "check the camera and target poses, or select views with in_front()"
        )
    return p


def in_front(p_cam) -> np.ndarray:
    """Which points a camera can see at all: z > 0 (m, camera frame), shape (N,) bool."""
    return np.asarray(p_cam, dtype=float)[..., 2] > 0


def _terms(intr: Intrinsics, p: np.ndarray):
    a = p[:, 0] / p[:, 2]
    b = p[:, 1] / p[:, 2]
    r2 = a * a + b * b
    radial = 1.0 + r2 * (intr.k1 + r2 * (intr.k2 + r2 * intr.k3))
    xd = a * radial + 2.0 * intr.p1 * a * b + intr.p2 * (r2 + 2.0 * a * a)
    yd = b * radial + intr.p1 * (r2 + 2.0 * b * b) + 2.0 * intr.p2 * a * b
    return a, b, r2, radial, xd, yd


def project(intr: Intrinsics, p_cam) -> np.ndarray:
    """Pixels of points given in the camera frame: OpenCV's model (module docstring).

    Parameters
    ----------
    intr : Intrinsics
    p_cam : array-like, shape (N, 3)
        Points in the camera frame, m; every z must be > 0.

    Returns
    -------
    ndarray, shape (N, 2)
        (u, v), pixels.

    Raises
    ------
    CalibrationError
        When a point is behind the camera or in its plane (z ≤ 0): never projected.
    """
    p = _points(p_cam, "project")
    _, _, _, _, xd, yd = _terms(intr, p)
    return np.stack([intr.fx * xd + intr.cx, intr.fy * yd + intr.cy], axis=1)


def jacobian_point(intr: Intrinsics, p_cam) -> np.ndarray:
    """Exact ∂(u, v)/∂p_cam, pixels per m, shape (N, 2, 3). Points as for `project`."""
    p = _points(p_cam, "jacobian_point")
    a, b, r2, radial, _, _ = _terms(intr, p)
    dradial = intr.k1 + r2 * (2.0 * intr.k2 + 3.0 * r2 * intr.k3)  # ∂radial/∂r²
    # ∂(x'', y'')/∂(x', y')
    dxa = radial + 2.0 * a * a * dradial + 2.0 * intr.p1 * b + 6.0 * intr.p2 * a
    dxb = 2.0 * a * b * dradial + 2.0 * intr.p1 * a + 2.0 * intr.p2 * b
    dya = dxb
    dyb = radial + 2.0 * b * b * dradial + 6.0 * intr.p1 * b + 2.0 * intr.p2 * a
    iz = 1.0 / p[:, 2]
    # ∂x'/∂p = (1/z, 0, −x'/z), ∂y'/∂p = (0, 1/z, −y'/z)
    J = np.empty((len(p), 2, 3))
    J[:, 0, 0] = intr.fx * dxa * iz
    J[:, 0, 1] = intr.fx * dxb * iz
    J[:, 0, 2] = -intr.fx * (dxa * a + dxb * b) * iz
    J[:, 1, 0] = intr.fy * dya * iz
    J[:, 1, 1] = intr.fy * dyb * iz
    J[:, 1, 2] = -intr.fy * (dya * a + dyb * b) * iz
    return J


def jacobian_intrinsics(intr: Intrinsics, p_cam) -> np.ndarray:
    """Exact ∂(u, v)/∂(fx, fy, cx, cy, k1, k2, p1, p2, k3), shape (N, 2, 9).

    Columns in `INTRINSIC_NAMES` order: pixels per pixel for fx..cy, pixels per unit
    coefficient for the distortion terms. Points as for `project`.
    """
    p = _points(p_cam, "jacobian_intrinsics")
    a, b, r2, _, xd, yd = _terms(intr, p)
    J = np.zeros((len(p), 2, 9))
    J[:, 0, 0] = xd
    J[:, 1, 1] = yd
    J[:, 0, 2] = 1.0
    J[:, 1, 3] = 1.0
    r4 = r2 * r2
    J[:, 0, 4], J[:, 1, 4] = intr.fx * a * r2, intr.fy * b * r2
    J[:, 0, 5], J[:, 1, 5] = intr.fx * a * r4, intr.fy * b * r4
    J[:, 0, 6], J[:, 1, 6] = intr.fx * 2.0 * a * b, intr.fy * (r2 + 2.0 * b * b)
    J[:, 0, 7], J[:, 1, 7] = intr.fx * (r2 + 2.0 * a * a), intr.fy * 2.0 * a * b
    J[:, 0, 8], J[:, 1, 8] = intr.fx * a * r4 * r2, intr.fy * b * r4 * r2
    return J


def radially_monotonic(intr: Intrinsics, p_cam) -> np.ndarray:
    """Whether the radial distortion still grows with the radius at each point, (N,) bool.

    The polynomial ``r · radial(r²)`` folds back beyond some radius when k1..k3 have mixed
    signs: there two different rays land on one pixel and the model's pixel is not what the
    lens shows. Views used for calibration should keep every point where
    ``d(r · radial)/dr = radial + 2 r² ∂radial/∂r² > 0``. Points as for `project`.
    """
    p = _points(p_cam, "radially_monotonic")
    _, _, r2, radial, _, _ = _terms(intr, p)
    dradial = intr.k1 + r2 * (2.0 * intr.k2 + 3.0 * r2 * intr.k3)
    return radial + 2.0 * r2 * dradial > 0
