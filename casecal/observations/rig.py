"""A camera and a robot as one robot whose frames are the camera's and the board's.

The fit of a camera calibration is the fit of a robot (`casecal.identify`): what the
camera sees of the board is a rigid chain from the camera through the robot to the
board, so the robot's base and tool frames can carry the two unknown poses:

- eye-to-hand (camera fixed, board on the flange): base = T_cam←robot base, tool =
  T_flange←board; the board's corners in the camera frame are ``fk(q) · c``;
- eye-in-hand (camera on the flange, board fixed): base = T_board←robot base, tool =
  T_flange←cam; the corners in the camera frame are ``fk(q)⁻¹ · c``.

The robot's own base and tool frames cannot be told from the camera's and the board's
poses (only their products are seen); the calibrated robot keeps the user's, and the
fitted camera and board poses absorb the rest (`fitted_setup`). The nine intrinsics ride
along as parameters of an error term that moves no joint (`INTRINSIC_PARAMETERS`), so
the rounds, the rank, the covariance and the table treat them like any other parameter.
"""

from __future__ import annotations

import dataclasses

import casadi as ca
import numpy as np

from ..errors import CalibrationError
from ..model.frames import rpy_from_matrix
from ..model.parameters import Unit
from ..model.robot import Frame, Robot, Session
from ..model.terms import ErrorTerm
from .camera import INTRINSIC_NAMES, Intrinsics
from .simulate import CameraSetup, inverse

INTRINSIC_PARAMETERS = tuple(f"camera_{n}" for n in INTRINSIC_NAMES)
"""The intrinsics as the fit's parameters: ``camera_fx`` … ``camera_k3``."""

PIXEL = ("px", Unit("px", 1.0, 50.0, 5.0, 10.0))
"""Focal lengths and the principal point: a datasheet's focal length is a few percent off
(tens of pixels); a standard error past 5 px is poorly determined."""

COEFFICIENT = ("1", Unit("", 1.0, 0.5, 0.05, 0.1))
"""Distortion coefficients (dimensionless)."""

KIND = "camera_intrinsics"


def _moves_nothing(ctx, term) -> ca.SX:
    return ca.SX(0.0)


def rig_robot(robot: Robot, setup: CameraSetup, later=()) -> Robot:
    """`robot` with the camera's and the board's poses as its base and tool frames, and
    the intrinsics as parameters (module doc).

    Raises
    ------
    CalibrationError
        For a tree, a robot with sessions or inputs, or one without a revolute joint
        (the intrinsics' term sits on one).
    """
    if robot.is_tree:
        raise CalibrationError(
            f"robot {robot.name!r} is a tree; camera calibration supports serial robots only "
            "(one tool frame holding the camera or the board)"
        )
    if robot.sessions or robot.inputs:
        raise CalibrationError(
            "camera calibration of a robot with sessions or per-pose inputs is not supported "
            "yet; give the robot without them (the views' sessions are "
            "PixelMeasurements.session's)"
        )
    if "R" not in robot.joint_types:
        raise CalibrationError(
            f"robot {robot.name!r} has no revolute joint; camera calibration needs one"
        )
    clash = sorted(set(robot.parameter_names) & set(INTRINSIC_PARAMETERS))
    if clash:
        raise CalibrationError(
            f"robot {robot.name!r} has parameters named like the camera's ({', '.join(clash)}); "
            "rename them"
        )
    B, Tl = robot.base.matrix(), robot.tool.matrix()
    base = _base(setup, B)
    tool = Tl @ (setup.target if setup.mode == "eye_to_hand" else setup.camera)
    sessions = tuple(Session(label, _frame(_base(other, B))) for label, other in later)
    units = (PIXEL,) * 4 + (COEFFICIENT,) * 5
    term = ErrorTerm(
        KIND,
        robot.joint_types.index("R") + 1,
        INTRINSIC_PARAMETERS,
        _moves_nothing,
        values=tuple(setup.intrinsics.vector().tolist()),
        units=units,
    )
    rig = dataclasses.replace(robot, base=_frame(base), tool=_frame(tool), sessions=sessions)
    return rig.with_terms(term)


def _base(setup: CameraSetup, B: np.ndarray) -> np.ndarray:
    """The rig's base frame: the robot's base seen from the camera (eye-to-hand) or from
    the board (eye-in-hand)."""
    return inverse(setup.camera if setup.mode == "eye_to_hand" else setup.target) @ B


def is_rig(robot: Robot) -> bool:
    """Whether `robot` is a camera rig (`rig_robot`)."""
    return any(t.kind == KIND for t in robot.terms)


def moves_robot(robot: Robot, names) -> np.ndarray:
    """Which of `names` move the robot's own tool in its own base frame, (k,) bool.

    All of them for a robot; for a rig, not its frames (the camera's and the board's
    poses) nor the lens: their uncertainty is the camera's, not the calibrated robot's,
    and judging what a calibration gains across the workspace leaves them out.
    """
    if not is_rig(robot):
        return np.ones(len(names), dtype=bool)
    return np.array(
        [not n.startswith(("base_", "tool_")) and n not in INTRINSIC_PARAMETERS for n in names],
        dtype=bool,
    )


def intrinsics_of(rig: Robot) -> Intrinsics:
    """The intrinsics a rig robot carries."""
    return Intrinsics.from_vector([rig.parameters[n] for n in INTRINSIC_PARAMETERS])


def fitted_setup(rig: Robot, robot: Robot, setup: CameraSetup, session: int = 0) -> CameraSetup:
    """The camera a fitted `rig` stands for in its `session` (0: the first), with
    `robot`'s own base and tool frames.

    ``fk = base · chain · tool`` of the rig equals the camera-to-board chain; with the
    user's base B and tool Tl kept, the camera and board poses are what makes the products
    equal (module doc).
    """
    B, Tl = robot.base.matrix(), robot.tool.matrix()
    frame = rig.base if session == 0 else rig.sessions[session - 1].base
    base, tool = frame.matrix(), rig.tool.matrix()
    if setup.mode == "eye_to_hand":
        camera, target = B @ inverse(base), inverse(Tl) @ tool
    else:
        target, camera = B @ inverse(base), inverse(Tl) @ tool
    return CameraSetup(
        setup.mode,
        _clean(camera),
        _clean(target),
        intrinsics_of(rig),
        setup.board,
        setup.image_size,
    )


def robot_of(rig: Robot, robot: Robot) -> Robot:
    """`robot` with the joint parameters a fitted `rig` carries (its frames unchanged)."""
    joint = {
        n: v
        for n, v in rig.parameters.items()
        if n in robot.parameter_names and not n.startswith(("base_", "tool_"))
    }
    return robot.with_parameters(joint)


def _frame(T: np.ndarray) -> Frame:
    return Frame(tuple(T[:3, 3].tolist()), tuple(rpy_from_matrix(T[:3, :3])))


def _clean(T: np.ndarray) -> np.ndarray:
    """A rigid transform re-orthonormalised (products of transforms drift by 1e-16)."""
    U, _, Vt = np.linalg.svd(T[:3, :3])
    out = T.copy()
    out[:3, :3] = U @ Vt
    out[3] = (0.0, 0.0, 0.0, 1.0)
    return out
