"""Camera measurements: the pixels of a checkerboard's corners in many robot poses.

`PixelMeasurements` is what `casecal.identify` takes for a camera calibration (the camera
on the flange or fixed, `casecal.observations.simulate.CameraSetup`); `simulate_camera`
makes them from a true robot and setup. The fit estimates the robot's parameters, the
camera's and the board's poses and (unless told they are known) the nine intrinsics,
starting from the nominal `setup` (`casecal.identification.camera_fit`).
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

import numpy as np

from ..errors import CalibrationError
from ..model.parameters import check_session_label
from .simulate import CameraSetup, simulate_pixels

OUTSIDE_PX = 1.0
"""How far (px) past the image's edge a detected corner may lie (sub-pixel refinement
near the border) before the image size and the pixels are taken to disagree."""


@dataclass(frozen=True, eq=False)
class PixelMeasurements:
    """Joint values and the corners' pixels seen in each pose.

    Attributes
    ----------
    q : ndarray, shape (N, dof)
        Joint values of the N views, rad (R) or m (P), the controller's.
    pixels : ndarray, shape (N, corners, 2)
        Measured (u, v) of every corner of ``setup.board``, px, in
        `casecal.observations.target.Checkerboard.corners` order; NaN (both u and v) for
        a corner the detector did not find in that view.
    setup : CameraSetup
        The nominal camera: mode, camera and board poses, intrinsics, board. The fit
        starts here; the poses should be right to centimetres and degrees, the intrinsics
        to a few percent (a datasheet, or OpenCV's ``calibrateCamera``).
    sigma_px : float
        Standard deviation of a pixel coordinate's noise, px (> 0).
    fit_intrinsics : bool
        Estimate the intrinsics (default). False: they are known (``setup.intrinsics``
        from a separate camera calibration) and held.
    session : ndarray of str, shape (N,), optional
        Each view's session: the board (eye-in-hand) or the camera (eye-to-hand) placed
        anew, so that the views cover more of the joint space. The first label's views
        are seen with `setup`; every later label's with its own in `setups`.
    setups : dict of str to CameraSetup, optional
        The nominal camera of each later session: the same mode, lens, board and image,
        the moved pose its own (the camera's eye-to-hand, the board's eye-in-hand).
    """

    q: np.ndarray
    pixels: np.ndarray
    setup: CameraSetup
    sigma_px: float
    fit_intrinsics: bool = True
    session: np.ndarray | None = None
    setups: dict | None = None

    def __post_init__(self) -> None:
        q = np.asarray(self.q, dtype=float)
        uv = np.asarray(self.pixels, dtype=float)
        if q.ndim != 2 or not np.all(np.isfinite(q)):
            raise CalibrationError(
                f"PixelMeasurements: joint values of shape {q.shape}; give (N, dof), all finite"
            )
        if not isinstance(self.setup, CameraSetup):
            raise CalibrationError("PixelMeasurements: setup must be a CameraSetup")
        m = self.setup.board.n_corners
        if uv.shape != (len(q), m, 2):
            raise CalibrationError(
                f"PixelMeasurements: pixels of shape {uv.shape}; give ({len(q)}, {m}, 2): "
                f"(u, v) of the board's {m} corners in each of the {len(q)} views"
            )
        missing = np.isnan(uv)
        if np.any(missing[..., 0] != missing[..., 1]) or np.any(np.isinf(uv)):
            raise CalibrationError(
                "PixelMeasurements: a corner has one coordinate missing (NaN) and not the other, "
                "or an infinite one; give both u and v, or NaN for both where it was not found"
            )
        if np.any(missing[..., 0].all(axis=1)):
            first = int(np.flatnonzero(missing[..., 0].all(axis=1))[0])
            raise CalibrationError(
                f"PixelMeasurements: view {first} has no corner found; leave such views out"
            )
        width, height = self.setup.image_size
        with np.errstate(invalid="ignore"):
            outside = (
                (uv[..., 0] < -OUTSIDE_PX - 0.5)
                | (uv[..., 0] > width - 0.5 + OUTSIDE_PX)
                | (uv[..., 1] < -OUTSIDE_PX - 0.5)
                | (uv[..., 1] > height - 0.5 + OUTSIDE_PX)
            )
        if outside.any():
            view, corner = (int(v[0]) for v in np.nonzero(outside))
            raise CalibrationError(
                f"PixelMeasurements: {int(outside.sum())} corners lie outside the setup's "
                f"{width} × {height} image (first: view {view}, corner {corner} at "
                f"{uv[view, corner].round(1).tolist()} px); give the camera's image_size, "
                "and pixels of that image (u along its rows, v down)"
            )
        sigma = self.sigma_px
        if isinstance(sigma, np.ndarray) and sigma.ndim == 0:
            sigma = sigma.item()
        if isinstance(sigma, bool | np.bool_) or not (
            isinstance(sigma, numbers.Real) and math.isfinite(sigma) and sigma > 0
        ):
            raise CalibrationError(
                f"PixelMeasurements: sigma_px = {sigma!r}; give the pixel noise, a number > 0 "
                "px (a detector's sub-pixel corners: 0.1–0.5 px)"
            )
        for name, a in (("q", q), ("pixels", uv)):
            a.setflags(write=False)
            object.__setattr__(self, name, a)
        if not isinstance(self.fit_intrinsics, bool | np.bool_):
            raise CalibrationError(
                f"PixelMeasurements: fit_intrinsics = {self.fit_intrinsics!r}; give True (the "
                "intrinsics are estimated) or False (they are known)"
            )
        object.__setattr__(self, "sigma_px", float(sigma))
        object.__setattr__(self, "fit_intrinsics", bool(self.fit_intrinsics))
        self._check_sessions(len(q))

    @property
    def n_poses(self) -> int:
        """Number of views N."""
        return len(self.q)

    @property
    def found(self) -> np.ndarray:
        """Which corners were found in which view, (N, corners) bool."""
        return ~np.isnan(self.pixels[..., 0])

    def _check_sessions(self, n: int) -> None:
        if self.session is None:
            if self.setups:
                raise CalibrationError(
                    "PixelMeasurements: setups without a session per view; give session="
                )
            return
        session = np.asarray(self.session)
        if session.shape != (n,):
            raise CalibrationError(
                f"PixelMeasurements: session of shape {session.shape}; give one label per view"
            )
        labels = list(dict.fromkeys(session.tolist()))
        for label in labels:
            check_session_label(label, "PixelMeasurements.session")
        setups = dict(self.setups or {})
        later = labels[1:]
        if sorted(setups) != sorted(later):
            raise CalibrationError(
                f"PixelMeasurements: sessions {labels}: give setups= a nominal camera for each "
                f"session after the first ({', '.join(later) or 'none'}), got "
                f"{', '.join(map(str, setups)) or 'none'}"
            )
        first = self.setup
        for label, other in setups.items():
            same = (
                isinstance(other, CameraSetup)
                and other.mode == first.mode
                and other.board == first.board
                and other.intrinsics == first.intrinsics
                and other.image_size == first.image_size
            )
            moved = "camera" if first.mode == "eye_to_hand" else "target"
            kept = "target" if moved == "camera" else "camera"
            if not same or not np.array_equal(getattr(other, kept), getattr(first, kept)):
                raise CalibrationError(
                    f"PixelMeasurements: session {label!r}'s setup must be the first's with "
                    f"only its {moved} pose moved (one lens, board and image; the "
                    f"{kept}'s pose shared, {first.mode})"
                )
        session.setflags(write=False)
        object.__setattr__(self, "session", session)
        object.__setattr__(self, "setups", setups)

    @property
    def labels(self) -> tuple[str, ...]:
        """The sessions in order of appearance (one, "", without sessions)."""
        if self.session is None:
            return ("",)
        return tuple(dict.fromkeys(self.session.tolist()))

    def setup_of(self, label: str) -> CameraSetup:
        """The nominal camera of session `label`."""
        return self.setup if label == self.labels[0] else self.setups[label]

    def subset(self, rows) -> PixelMeasurements:
        """The views `rows` (indices or a boolean mask); the sessions they keep, the first
        of them seen with its own setup."""
        if self.session is None:
            return PixelMeasurements(
                self.q[rows], self.pixels[rows], self.setup, self.sigma_px, self.fit_intrinsics
            )
        session = self.session[rows]
        labels = list(dict.fromkeys(session.tolist()))
        setups = {label: self.setup_of(label) for label in labels[1:]}
        return PixelMeasurements(
            self.q[rows],
            self.pixels[rows],
            self.setup_of(labels[0]),
            self.sigma_px,
            self.fit_intrinsics,
            session,
            setups,
        )


def simulate_camera(
    robot, q, setup: CameraSetup, sigma_px: float, seed=None, fit_intrinsics: bool = True
) -> PixelMeasurements:
    """Pixels a camera would measure of `robot` (the truth) in `setup` (the true camera).

    Parameters
    ----------
    robot : casecal.Robot
        The true robot.
    q : array-like, shape (N, dof)
        Joint values, rad (R) or m (P); every view must see the whole board (pick them
        with `casecal.observations.simulate.select_views`).
    setup : CameraSetup
        The true camera; the returned measurements carry it as their nominal: give them
        another with ``dataclasses.replace(meas, setup=nominal)`` to fit from elsewhere.
    sigma_px : float
        Pixel noise σ, px (> 0: the fit weighs by it).
    seed : int or numpy Generator
        For the noise.

    Returns
    -------
    PixelMeasurements
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    uv = simulate_pixels(robot, q, setup, sigma_px=sigma_px, seed=seed)
    return PixelMeasurements(q, uv, setup, sigma_px, fit_intrinsics)
