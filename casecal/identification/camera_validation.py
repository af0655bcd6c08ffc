"""Held-out validation of a camera calibration: pixels of views the fit never saw.

As for a tracker (`casecal.identification.validation`), each model gets the frames that
may have moved since the calibration refitted to the held-out views first — here the
camera's and the board's poses — with its joint parameters and its lens as they are; what
remains is what the calibration did or did not fix. Before: the nominal robot with the
nominal lens; after: the calibrated robot with the fitted lens.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..errors import CalibrationError
from ..model.robot import Robot
from ..observations.pixels import PixelMeasurements
from ..observations.simulate import CameraSetup
from .camera_fit import identify_camera
from .held_out import ErrorStats, refitted


@dataclass(frozen=True)
class CameraValidation:
    """Pixel errors of the nominal and of the calibrated model on held-out views.

    Attributes
    ----------
    before, after : ErrorStats
        Of the corners found, px (`n_points`: how many).
    n_views : int
    sigma_px : float
        The views' stated pixel noise: a model at the floor has RMS |(Δu, Δv)| ≈ √2 σ.
    """

    before: ErrorStats
    after: ErrorStats
    n_views: int
    sigma_px: float

    def __str__(self) -> str:
        rows = [
            f"{self.n_views} held-out views, {self.after.n_points} corners; camera and board "
            "poses refitted to them, the joints' parameters and the lens as calibrated",
            f"{'':8}{'RMS':>10}{'mean':>10}{'max':>10}   (px, |(du, dv)|; noise floor "
            f"{np.sqrt(2) * self.sigma_px:.3g} px RMS)",
        ]
        for label, s in (("before", self.before), ("after", self.after)):
            rows.append(f"{label:8}{s.rms:10.4f}{s.mean:10.4f}{s.max:10.4f}")
        return "\n".join(rows)


def validate_camera(
    calibrated: Robot, camera: CameraSetup, measurements: PixelMeasurements, nominal: Robot
) -> CameraValidation:
    """Compare `nominal` (with the views' nominal camera) and `calibrated` (with the fitted
    `camera`, `Calibration.camera.setup`) on held-out views, poses refitted (module doc)."""
    if not isinstance(camera, CameraSetup):
        raise CalibrationError(
            "validating camera views needs the fitted camera: validate(cal.robot, views, "
            "nominal, camera=cal.camera.setup)"
        )
    if camera.mode != measurements.setup.mode or camera.board != measurements.setup.board:
        raise CalibrationError(
            "the held-out views' camera has another mode or board than the calibration's; "
            "validate views of the same camera and board"
        )
    # the poses start from the views' nominal ones and are refitted; only the lens differs
    lens = camera.intrinsics
    fitted = dataclasses.replace(
        measurements,
        setup=dataclasses.replace(measurements.setup, intrinsics=lens),
        setups={k: dataclasses.replace(v, intrinsics=lens) for k, v in measurements.setups.items()}
        if measurements.setups
        else None,
        fit_intrinsics=False,
    )
    known = dataclasses.replace(measurements, fit_intrinsics=False)
    before = _refit(nominal, known)
    after = _refit(calibrated, fitted)
    return CameraValidation(before, after, measurements.n_poses, measurements.sigma_px)


def _refit(robot: Robot, measurements: PixelMeasurements) -> ErrorStats:
    """Pixel errors of `robot` and the measurements' lens after refitting the poses alone."""
    cal = refitted(  # the poses alone: no joint parameter asked for
        lambda: identify_camera(robot, measurements, ["base_*"]),
        "the camera and board poses",
        "the held-out views",
    )
    return ErrorStats.of(cal.camera.pixel_residuals, dim=2)
