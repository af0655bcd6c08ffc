"""Held-out validation: how well a calibrated robot predicts measurements it was not fit to."""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from ..data.measurements import Measurements
from ..design.poses import rng_from
from ..errors import CalibrationError
from ..model.robot import Robot
from ..observations.pixels import PixelMeasurements
from .camera_validation import validate_camera
from .fit import identify
from .held_out import ErrorStats, refitted


@dataclass(frozen=True)
class Validation:
    """Errors of the nominal and of the calibrated model on held-out measurements.

    Both models get their frames (base, tool position, reflectors; the tool's orientation
    too where orientations were measured) refitted to these measurements first, since the
    instrument and the probe may have moved; the DH parameters are not touched, so what
    remains is what the calibration did or did not fix.

    Attributes
    ----------
    before, after : ErrorStats
        Position errors, m.
    n_poses : int
    rotation_before, rotation_after : ErrorStats or None
        Where orientations were measured: the angle of each pose's orientation error
        (``|log(R_meas R_modelᵀ)|``), rad.
    """

    before: ErrorStats
    after: ErrorStats
    n_poses: int
    rotation_before: ErrorStats | None = None
    rotation_after: ErrorStats | None = None

    def __str__(self) -> str:
        rows = [
            f"{self.n_poses} held-out poses, {self.after.n_points} measured points; "
            "frames refitted to them, the joints' parameters as calibrated",
            f"{'':8}{'RMS':>10}{'mean':>10}{'max':>10}   (mm)",
        ]
        for label, s in (("before", self.before), ("after", self.after)):
            rows.append(f"{label:8}{s.rms * 1e3:10.4f}{s.mean * 1e3:10.4f}{s.max * 1e3:10.4f}")
        if self.rotation_before is not None and self.rotation_after is not None:
            rows.append(f"{'':8}{'RMS':>10}{'mean':>10}{'max':>10}   (deg, orientation)")
            for label, s in (("before", self.rotation_before), ("after", self.rotation_after)):
                d = np.degrees([s.rms, s.mean, s.max])
                rows.append(f"{label:8}{d[0]:10.4f}{d[1]:10.4f}{d[2]:10.4f}")
        return "\n".join(rows)


def _rotation_stats(vectors: np.ndarray) -> ErrorStats:
    angle = np.linalg.norm(vectors, axis=1)
    return ErrorStats(
        float(np.sqrt(np.mean(angle**2))), float(angle.mean()), float(angle.max()), angle.size
    )


def refit_frames(robot: Robot, measurements: Measurements) -> tuple[ErrorStats, ErrorStats | None]:
    """Errors of `robot` on `measurements` after fitting its frames alone to them.

    Returns
    -------
    positions : ErrorStats
        m.
    orientations : ErrorStats or None
        rad; None when no orientations were measured.
    """
    # a re-mounted probe turns as well as moves: where orientations are measured, the
    # tool's orientation is a frame to refit (fixed, it trades positions for angles)
    tool = ("tool_x", "tool_y", "tool_z")
    if measurements.orientations is not None:
        tool += ("tool_rx", "tool_ry", "tool_rz")
    if robot.is_tree:  # where each tip's marker sits: its position, as a tool's
        tool += tuple(f"{t}.{c}" for t in robot.tips for c in "xyz")
    frames = [n for n in robot.parameter_names if n.startswith(("base_", "point")) or n in tool]
    cal = refitted(
        lambda: identify(robot, measurements, frames, "gauss-newton"),
        "the frames",
        "the held-out data",
        "; measure more poses",
    )
    rotations = cal.orientation_residuals
    return ErrorStats.of(cal.residuals), None if rotations is None else _rotation_stats(rotations)


def validate(calibrated: Robot, measurements: Measurements, nominal: Robot, camera=None):
    """Compare `nominal` and `calibrated` on held-out `measurements` (frames refitted).

    Parameters
    ----------
    calibrated, nominal : Robot
        The same structure; the nominal gets the calibrated robot's reflector layout as
        its starting guess when it has none.
    measurements : Measurements or PixelMeasurements
        Poses (or a camera's views) not used in the calibration.
    camera : CameraSetup, optional
        For views: the calibration's fitted camera (`Calibration.camera.setup`).

    Returns
    -------
    Validation, or `casecal.identification.camera_validation.CameraValidation` for views.
    """
    if isinstance(measurements, PixelMeasurements):
        return validate_camera(calibrated, camera, measurements, nominal)
    if not isinstance(measurements, Measurements):
        raise CalibrationError(
            f"validate takes Measurements or PixelMeasurements, not {type(measurements).__name__}"
        )
    if camera is not None:
        raise CalibrationError("camera= is for a camera's views (PixelMeasurements) only")
    if measurements.contact:
        raise CalibrationError(
            "validating on contact sessions (fixed points, planes) is not supported yet: "
            "their held-out errors are not positions; hold out measured points, or compare "
            "the calibrated robot's contact residuals (Calibration.residuals)"
        )
    if nominal.sessions:  # a session fit's nominal (`Calibration.nominal`): the robot itself
        nominal = nominal.with_sessions(())
    if calibrated.sessions:
        calibrated = calibrated.with_sessions(())
    if nominal.points == () and calibrated.points:
        nominal = nominal.with_points(calibrated.points)
    before, rotation_before = refit_frames(nominal, measurements)
    after, rotation_after = refit_frames(calibrated, measurements)
    reach = calibrated.reach
    if reach and after.rms > MISFIT * reach:
        warnings.warn(
            f"{calibrated.name} misses these measurements by {after.rms * 1e3:.4g} mm RMS "
            f"({after.rms / reach:.0%} of its reach) even with its frames refitted: are they "
            "this robot's, with the joints in its order, zeros and units?",
            stacklevel=2,
        )
    return Validation(before, after, measurements.n_poses, rotation_before, rotation_after)


MISFIT = 0.02
"""Fraction of a robot's reach above which its held-out RMS error, frames refitted, says
the measurements are not of this robot (or not in its joint conventions): calibrated arms
miss by well under 0.1 %, uncalibrated ones by under 0.5 %."""


def split(measurements, fraction: float, seed=0):
    """Random (fit, held-out) split of the poses (or a camera's views); `fraction` of them
    are held out."""
    if not isinstance(fraction, int | float) or not 0 < fraction < 1:
        raise CalibrationError(f"holdout fraction must be between 0 and 1, got {fraction}")
    n = measurements.n_poses
    k = round(fraction * n)
    if k < 1 or n - k < 1:
        raise CalibrationError(f"holdout {fraction} of {n} poses leaves no poses on one side")
    held = np.zeros(n, bool)
    held[rng_from(seed).choice(n, size=k, replace=False)] = True
    if isinstance(measurements, PixelMeasurements):
        return measurements.subset(~held), measurements.subset(held)
    return measurements.take(~held), measurements.take(held)
