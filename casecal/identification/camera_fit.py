"""`identify` for a camera: the robot, the hand-eye and board poses and the intrinsics.

The camera's pixels are residual rows of the one fitting path (`PixelProblem`): the rig
robot of `casecal.observations.rig` carries the camera's and the board's poses as its
base and tool frames and the intrinsics as parameters, and the fit runs as any other —
reference frames first (a hand-eye calibration of the nominal robot: the "before"), then
the rounds, the noise-aware rank, the audit and the covariance. The result is a
`Calibration` whose `robot` is the user's robot with its joint parameters calibrated (its
own base and tool frames), and whose `camera` says where the camera and the board are and
what the lens is (`CameraFit`).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from functools import partial

import numpy as np

from ..errors import CalibrationError
from ..model.parameters import select
from ..model.robot import Robot
from ..observations.camera import project
from ..observations.pixels import PixelMeasurements
from ..observations.rig import INTRINSIC_PARAMETERS, fitted_setup, rig_robot, robot_of
from ..observations.simulate import CameraSetup, points_in_camera
from .analysis import represent, selection
from .audit import Audit, audit
from .calibration import Calibration
from .contact import plausible_error
from .facts import gather
from .fitting import check_iterations, outcome_fields, rms_of, shared_problems, verdict
from .pixel_problem import PixelProblem, View
from .reference import FRAME_PREFIXES, frame_parameters, frames_fitted
from .rounds import Settings, fit_in_rounds
from .scale import board_size_check
from .solvers import SOLVERS
from .summary import outliers_lead, stand_out

SCALE = (
    "The board's spacing sets the scale: every length is in units of its square, and a board "
    "printed 1% large makes every length of the arm 1% long with no residual to show it; "
    "measure the printed board over many squares."
)

FRAMES = ("base_*", "tool_*")
"""The camera's and the board's poses (the rig's frames): always estimated."""


@dataclass(frozen=True, eq=False)
class CameraFit:
    """Where the camera and the board are, and what the lens is, after a camera calibration.

    Attributes
    ----------
    setup, setup_before : CameraSetup
        The fitted camera (poses with the calibrated robot's own base and tool frames,
        intrinsics), and the reference before calibration: the nominal robot and lens with
        the two poses fitted (a hand-eye calibration alone).
    pixel_residuals, pixel_residuals_before : ndarray, shape (N, corners, 2)
        Measured minus modelled pixels after and before, px; NaN where a corner was not found.
    sigma_px : float
        The pixel noise the fit was weighed with, px.
    sessions : dict of str to CameraSetup
        With sessions (`PixelMeasurements.session`): each session's fitted camera, the
        first's being `setup`; empty without.
    """

    setup: CameraSetup
    setup_before: CameraSetup
    pixel_residuals: np.ndarray
    pixel_residuals_before: np.ndarray
    sigma_px: float
    sessions: dict = field(default_factory=dict)

    @property
    def rms_px(self) -> float:
        """RMS reprojection error per coordinate after calibration, px."""
        return float(np.sqrt(np.nanmean(self.pixel_residuals**2)))

    @property
    def rms_px_before(self) -> float:
        """RMS reprojection error per coordinate before (hand-eye only), px."""
        return float(np.sqrt(np.nanmean(self.pixel_residuals_before**2)))


def camera_names(robot: Robot, rig: Robot, parameters, fit_intrinsics: bool) -> list[str]:
    """The asked-for robot parameters, the rig's frames and (unless known) the intrinsics,
    in the rig's order. The robot's own frames are not the user's to ask for here: the
    camera sees only their products with the camera's and the board's poses."""
    asked = [n for n in selection(robot, parameters) if not n.startswith(FRAME_PREFIXES)]
    lens = list(INTRINSIC_PARAMETERS) if fit_intrinsics else []
    return select(rig.parameter_names, [*asked, *FRAMES, *lens])


def pixel_arrays(robot: Robot, measurements: PixelMeasurements):
    """The object-space data of a `PixelProblem` at the nominal camera: ``y`` (N, c, 3),
    ``w`` (N, 3) and its `View` (`casecal.identification.pixel_problem`)."""
    setup = measurements.setup
    p_cam = corners_in_camera(robot, measurements)
    depth = p_cam[..., 2].mean(axis=1)
    behind = np.flatnonzero(~np.all(p_cam[..., 2] > 0, axis=1))
    if behind.size:
        raise CalibrationError(
            f"the nominal camera and board put corners behind the camera in {behind.size} of "
            f"{len(depth)} views (first: {behind[:5].tolist()}); check the setup's poses "
            f"(mode {setup.mode!r}: camera = {_what(setup.mode, 'camera')}, target = "
            f"{_what(setup.mode, 'target')}) and the joint values' units"
        )
    intr = setup.intrinsics
    _check_order(measurements, project(intr, p_cam.reshape(-1, 3)).reshape((*p_cam.shape[:2], 2)))
    scale = depth[:, None] / np.array([intr.fx, intr.fy])  # m per px, (N, 2)
    found = measurements.found
    y = np.zeros((*found.shape, 3))
    y[..., :2] = np.where(found[..., None], measurements.pixels, 0.0) * scale[:, None, :]
    w = np.zeros((len(depth), 3))
    w[:, :2] = 1.0 / (measurements.sigma_px * scale)
    return y, w, View(setup.mode, setup.board.corners(), scale, found)


REVERSED = 3.0
"""A view whose corners lie this many times nearer the nominal prediction read backwards
than forwards has them in reverse order (and the other way round, forward)."""

FORWARD_SHARE = 0.75
"""The share of views that must read clearly forward for the others to be judged."""

FAR_PX = 20.0
"""RMS pixel error (px) of the camera and board poses fitted to the nominal robot and lens
past which a failed fit names the gross causes (units, mode, board, order) first."""


def _check_order(measurements: PixelMeasurements, predicted: np.ndarray) -> None:
    """Refuse views whose corners are in reverse order (a symmetric board's half turn).

    A detector returns a board whose rows + columns are even in either order
    (`casecal.observations.target.Checkerboard.symmetric`); a view read backwards is
    hundreds of pixels off everywhere, which the fit would take for a gross error. Judged
    only where most views clearly read forward at the nominal camera: a nominal camera
    rolled by half a turn reads every view backwards, which the fit of its pose mends.
    """
    if not measurements.setup.board.symmetric:
        return
    uv = measurements.pixels
    both = measurements.found & measurements.found[:, ::-1]  # corners found either way
    ahead = np.where(both, np.linalg.norm(uv - predicted, axis=2), np.nan)
    behind = np.where(both, np.linalg.norm(uv[:, ::-1] - predicted, axis=2), np.nan)
    with np.errstate(all="ignore"):
        ahead, behind = np.nanmedian(ahead, axis=1), np.nanmedian(behind, axis=1)
    forward = ahead * REVERSED < behind
    reversed_ = behind * REVERSED < ahead
    if not reversed_.any() or forward.sum() < FORWARD_SHARE * len(uv):
        return
    views = np.flatnonzero(reversed_)
    raise CalibrationError(
        f"{views.size} of {len(uv)} views (first: {views[:5].tolist()}) have their corners in "
        "reverse order while the others read forward: the board looks the same after a half "
        "turn, and a detector returns either order; put each view's corners in "
        "Checkerboard.corners order (reverse those views' rows), or use a board whose rows + "
        "columns are odd"
    )


def _what(mode: str, which: str) -> str:
    words = {
        ("eye_in_hand", "camera"): "T_tool←camera",
        ("eye_in_hand", "target"): "T_base←board",
        ("eye_to_hand", "camera"): "T_base←camera",
        ("eye_to_hand", "target"): "T_tool←board",
    }
    return words[(mode, which)]


def pixel_residuals(problem: PixelProblem, x: np.ndarray) -> np.ndarray:
    """Measured minus modelled pixels (N, c, 2), px; NaN where a corner was not found."""
    r = problem.point_residuals(x)[..., :2] / problem.view.scale[:, None, :]
    return np.where(problem.view.found[..., None], r, np.nan)


def corners_in_camera(robot: Robot, measurements: PixelMeasurements) -> np.ndarray:
    """The board's corners in the camera frame at the nominal camera of each view's
    session, m, (N, c, 3)."""
    if measurements.session is None:
        return points_in_camera(robot, measurements.q, measurements.setup)
    out = np.empty((*measurements.pixels.shape[:2], 3))
    for label in measurements.labels:
        rows = measurements.session == label
        out[rows] = points_in_camera(robot, measurements.q[rows], measurements.setup_of(label))
    return out


def camera_problem(robot: Robot, measurements: PixelMeasurements):
    """The rig and a `make(rig, names=..., kernel_names=..., memo=...)` of its problems."""
    labels = measurements.labels
    later = [(label, measurements.setup_of(label)) for label in labels[1:]]
    rig = rig_robot(robot, measurements.setup, later)
    if measurements.q.shape[1] != robot.dof:
        raise CalibrationError(
            f"camera measurements have {measurements.q.shape[1]} joint values per view but "
            f"robot {robot.name!r} has {robot.dof} joints; use the robot the data came from"
        )
    y, w, view = pixel_arrays(robot, measurements)
    q = measurements.q
    if later:  # each later session's indicator selects its own base (`Robot.sessions`)
        index = np.array([labels.index(label) for label in measurements.session.tolist()])
        indicators = np.zeros((len(q), len(later)))
        indicators[np.flatnonzero(index), index[index > 0] - 1] = 1.0
        q = np.ascontiguousarray(np.hstack([q, indicators]))
    return rig, partial(PixelProblem, q=q, y=y, w=w, view=view)


def identify_camera(
    robot: Robot,
    measurements: PixelMeasurements,
    parameters=None,
    method: str = "gauss-newton",
    *,
    max_iterations: int = 100,
    tolerance: float = 1e-10,
    truth: dict | None = None,
    progress=None,
) -> Calibration:
    """`casecal.identify` for camera measurements (module doc).

    Parameters
    ----------
    robot : Robot
        The nominal robot, serial, with its own base and tool frames (kept).
    measurements : PixelMeasurements
        Joint values, pixels, the nominal camera and the pixel σ.
    parameters : str, list of str or None
        The robot's parameters to identify, as for `identify` (its own base and tool
        frames are not among them: see `camera_names`); the camera's and the board's poses
        are always estimated, the intrinsics unless ``measurements.fit_intrinsics`` is
        False.
    method, max_iterations, tolerance, truth, progress
        As `identify`'s; `truth` may name the rig's parameters (``base_*`` are then the
        camera's or the board's pose, ``camera_fx`` … the lens).

    Returns
    -------
    Calibration
        ``measured == "pixels"``; `robot` is `robot` calibrated (its own frames),
        `nominal` the rig at the start, `camera` the fitted camera (`CameraFit`); the
        residuals are object-space lengths, m (`casecal.identification.pixel_problem`).
    """
    t0 = time.perf_counter()
    max_iterations, tolerance = check_iterations(max_iterations, tolerance)
    if method not in SOLVERS:
        raise CalibrationError(f"unknown method {method!r}; use one of {', '.join(SOLVERS)}")
    rig, make = camera_problem(robot, measurements)
    make = shared_problems(make)
    names = camera_names(robot, rig, parameters, measurements.fit_intrinsics)
    w = make(rig, names=names).w
    e0 = rms_of(make(rig, names=names), len(names))
    settings = Settings(method, max_iterations, tolerance, True, w, "linear", 3.0, {}, {}, progress)
    reference = frames_fitted(make, rig, names, settings, e0)  # hand-eye alone: "before"
    e_before = rms_of(make(reference, names=names), len(names))
    start = rig
    if method != "svd":  # the poses fitted: a start nearer the minimum
        start = rig.with_parameters({n: reference.parameters[n] for n in frame_parameters(names)})
    # the poses' fit absorbs much of the robot's error where the camera looks, as a
    # contact's frame does: what an uncertainty costs is judged against a plausible robot's
    e_rounds = max(e_before, plausible_error(start, names))
    out = fit_in_rounds(make, start, names, settings, e_rounds)
    got = gather(make, rig, start, reference, names, out, settings, e0, e_before)
    calibrated = robot_of(out.robot, robot)
    size = board_size_check(robot, calibrated, measurements.q, measurements.setup.board.spacing)
    checks = audit(got.facts)
    checks = (
        Audit((size, *checks.checks)) if size.passed is False else Audit((*checks.checks, size))
    )
    status, message = verdict(checks, out.solver_status, out.message)
    model_error = bool(checks.failures) and checks.failures[0].cause
    lead = status < 0 and outliers_lead(got.outliers, len(measurements.q)) and not model_error
    if lead:  # the likelier cause leads, as for a tracker's fit
        message = f"{stand_out(got.outliers, 'linear', 'pixels')}; {message}"
    x0 = np.zeros(len(out.estimated))
    cov, se = got.covariance, dict.fromkeys(names, float("nan"))
    se.update(zip(out.estimated, np.sqrt(np.diag(cov)).tolist(), strict=True))
    before = make(reference, names=names)
    camera = CameraFit(
        setup=fitted_setup(out.robot, robot, measurements.setup),
        setup_before=fitted_setup(reference, robot, measurements.setup),
        pixel_residuals=pixel_residuals(got.estimated, x0),
        pixel_residuals_before=pixel_residuals(before, np.zeros(len(names))),
        sigma_px=measurements.sigma_px,
        sessions={}
        if measurements.session is None
        else {
            label: fitted_setup(out.robot, robot, measurements.setup_of(label), k)
            for k, label in enumerate(measurements.labels)
        },
    )
    if status < 0 and camera.rms_px_before > FAR_PX:
        message = f"{gross_causes(camera.rms_px_before)}; {message}"
    final = got.at_end if out.end_analysis is not out.start_analysis else make(rig, names=names)
    cal = Calibration(
        **outcome_fields(out, got),
        method=method,
        nominal=rig,
        robot=calibrated,
        parameters=tuple(names),
        deviations=out.robot.deviations_from(rig, names),
        standard_errors=se,
        covariance=cov,
        residuals=got.estimated.point_residuals(x0).reshape(-1, 3),
        residuals_before=before.point_residuals(np.zeros(len(names))).reshape(-1, 3),
        status=status,
        message=message,
        sigma_known=True,
        wall_time=time.perf_counter() - t0,
        start_note=camera_note(measurements.setup.mode),
        outliers_lead=lead,
        audit=checks,
        representation=represent(
            final.reduced(np.zeros(len(names))).R,
            names,
            out.estimated,
            out.pruned,
            standard_errors=se,
            sizes=rig.sizes,
        ),
        measured="pixels",
        unmeasured=got.estimated._unmeasured.reshape(-1, 3),
        camera=camera,
    )
    mounted = _with_the_mount(cal, measurements.setup.mode)
    if mounted:
        cal = dataclasses.replace(cal, start_note=f"{cal.start_note} {mounted}")
    return cal.compare_to(truth) if truth is not None else cal


def _with_the_mount(cal: Calibration, mode: str) -> str:
    """Words for the held parameters the mount on the flange (the board eye-to-hand, the
    camera eye-in-hand) carries: `Calibration.robot` keeps them nominal, so its flange is
    off by their deviations, which the views cannot tell from the mount's; "" for none."""
    terms = {} if cal.representation is None else cal.representation.terms
    carried = []
    for name, pairs in terms.items():
        if name.startswith("tool_"):
            carried += [held for held, _ in pairs if held not in carried]
    if not carried:
        return ""
    mount = "board" if mode == "eye_to_hand" else "camera"
    return (
        f"{', '.join(carried)} stay nominal in the calibrated robot: the views see them only "
        f"together with the {mount}'s mount on the flange (Calibration.camera.setup's "
        f"{'target' if mount == 'board' else 'camera'}), which carries their deviations. "
        f"The robot's flange is right up to them, the mounted {mount} as well as the fit "
        "predicts: measure a tool's centre point on the calibrated robot, or give these "
        "parameters' values from elsewhere, before compensating for that tool."
    )


def gross_causes(rms_px: float) -> str:
    """Words for a camera fit that failed far from its data."""
    return (
        "even with the camera's and the board's poses fitted, the nominal robot and lens miss "
        f"the corners by {rms_px:.3g} px RMS: check the joint values' units (rad, not "
        "degrees), the mode (eye_in_hand: camera on the flange), Checkerboard(rows, cols) "
        "against OpenCV's patternSize=(cols, rows), the corners' order and (u, v) (u along "
        "the image's rows)"
    )


def camera_note(mode: str) -> str:
    """What the rig's frame parameters stand for, in words."""
    if mode == "eye_to_hand":
        return (
            "Camera calibration, eye-to-hand: base_* is the robot's base seen from the camera "
            "(T_camera←base), tool_* the board on the flange (T_flange←board); camera_* the "
            f"lens. Residuals are pixels seen at the board's distance (object space, mm). {SCALE}"
        )
    return (
        "Camera calibration, eye-in-hand: base_* is the robot's base seen from the board "
        "(T_board←base), tool_* the camera on the flange (T_flange←camera); camera_* the "
        f"lens. Residuals are pixels seen at the board's distance (object space, mm). {SCALE}"
    )
