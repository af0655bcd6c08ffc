"""Units checked at the door: measured points and joint values against the nominal robot.

A unit slip (metres in ``x_mm`` columns, inches, radians in ``q*_deg`` columns) does not
make data noisy: it makes them the measurements of another robot, often one the fit can
reach exactly (a PUMA 560 with every length shrunk 1000 times fits metres written as
millimetres to the rounding floor). So before any fit the data are compared with what the
nominal robot does at the same joint values:

- **positions**: the measured cloud against the nominal robot's cloud of measured points,
  by a similarity fit (rotation, translation and one scale, so that wherever the
  instrument stands does not matter). A cloud that is a faithful copy of the nominal one
  (relative residual ≤ `SHAPE`) at a scale far from 1 (beyond `SCALE_REFUSED`) is a unit
  slip, and refused, unless the nominal cloud is so nearly a rotation about one point
  (only the wrist moved) that a tool the model does not know could change its size
  (`unmodelled_tool_possible`): then the finding is a warning;
- **joints**: revolute values in degrees that read as radians stay within a turn (all
  within ±6.3, as radians in ``q*_deg`` columns are), or radians beyond a turn, are read
  the other way too; when the measured points fit the robot only in the other reading,
  the joint unit is refused. Small motions in degrees (every joint within ±3° of zero)
  fit the declared reading and pass. Values outside the joint limits stay a warning
  (`casecal.data.files`): a robot file's limits may be conservative.

A finding that is possible but not certain is a `CalibrationWarning`; the fit's own check
(`casecal.identification.scale`) then fails a calibrated robot that changed size.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from dataclasses import dataclass

import numpy as np

from ..errors import CalibrationError, CalibrationWarning
from ..model.robot import Robot
from .clouds import Similarity, rigid_rms, similarity  # noqa: F401 (re-export)

SHAPE = 0.2
"""Largest RMS residual of the similarity fit, relative to the measured cloud's RMS
spread, at which the measured cloud counts as a scaled copy of the nominal one (a real
robot's deviations leave a few per cent; a different pose set or robot, most of it)."""

SCALE_REFUSED = 3.0
"""A scaled copy of the nominal cloud more than this many times larger or smaller is a
unit slip: no deviation of a real robot, only a tool the model lacks, changes its size so."""

TOOL_SLACK = 2.0
"""How much more than `SHAPE` an unmodelled tool's leftover may be before it is excluded
as the reason for a change of size (`unmodelled_tool_possible`)."""

MIN_POINTS = 6
"""Fewer measured points than this cannot tell a shape from a scale (two fit any scale)."""

DOOR_POSES = 3000
"""At most this many poses, evenly spread over the file, are compared at the door."""

FACTOR_TOLERANCE = 1.15
"""A ratio within this factor of a known slip is named as that slip."""

_LENGTHS = {"m": 1.0, "mm": 1e-3, "um": 1e-6, "cm": 1e-2, "in": 0.0254, "km": 1e3}
_LENGTH_WORDS = {
    "m": "metres",
    "mm": "millimetres",
    "um": "micrometres",
    "cm": "centimetres",
    "in": "inches",
    "km": "kilometres",
}


def ratio_text(ratio: float) -> str:
    """``"1/1000 (0.001×) of"`` or ``"1000 times"`` for a spread ratio, to go before
    "what the robot reaches"."""
    if ratio < 1:
        inverse = 1 / ratio
        shown = f"{inverse:.4g}" if inverse < 100 else f"{inverse:.0f}"
        return f"1/{shown} ({ratio:.3g}×) of"
    return f"{ratio:.4g} times"


def length_unit_slip(ratio: float, declared: str = "m") -> str | None:
    """The unit the values are really in, if `ratio` (read over true size) is a known slip.

    Values read in `declared` ("m", "mm", "um") come out `ratio` times their true size
    when they really are in the returned unit ("m", "mm", "um", "cm", "in", "km").
    """
    s_declared = _LENGTHS[declared]
    for unit, s in _LENGTHS.items():
        if unit != declared and abs(math.log(s_declared / s / ratio)) < math.log(FACTOR_TOLERANCE):
            return unit
    return None


def api_unit_words(unit: str) -> str:
    """What values given as metres but really in `unit` are, in words."""
    if unit == "km":  # nobody measures robots in km: metres divided by 1000 once too often
        return "metres divided by 1000 (taken for millimetres)"
    return f"in {_LENGTH_WORDS[unit]}"


@dataclass(frozen=True)
class PositionFinding:
    """The measured cloud against the nominal robot's (module doc)."""

    ratio: float
    """Scale of the similarity fit of the nominal cloud onto the measured one."""
    shape_error: float
    tool_could_explain: bool
    """The nominal cloud is so nearly a rotation about one point (only the wrist turned)
    that a tool the robot file lacks could explain the size (`unmodelled_tool_possible`)."""
    refused: bool
    tip: str | None = None
    """A tree's tip whose points alone are off in size (the others' hid it), else None."""


@dataclass(frozen=True)
class JointFinding:
    """The joint values read in another unit fit the measured points (module doc)."""

    factor: float
    """What the values were multiplied by in the other reading (180/π or π/180)."""
    rms_declared: float
    rms_other: float
    largest: float
    """Largest |value| of the joints read the other way, in the declared unit (rad)."""
    refused: bool


def _nominal_points(robot: Robot, q: np.ndarray, m: int) -> np.ndarray | None:
    try:
        P = robot.measured_points(q)
    except (CalibrationError, ValueError):
        return None
    if P.shape[1] != m:
        P = np.repeat(P[:, :1], m, axis=1)  # reflectors not on the model: all at its tool
    return P


def rotating_residual(robot: Robot, q: np.ndarray, P: np.ndarray, tip: int | None = None) -> float:
    """How far the nominal cloud is from a rotation about one point: the relative RMS
    residual of ``P_ij - mean ≈ (R_i - mean R) u_j`` (a rotating offset u_j per point,
    R_i the tool's rotation); 0 when only the wrist turned about a fixed point, 0 also
    when the robot's rotations cannot be had (then nothing is excluded). `tip`: `P` is
    that tip's of a tree."""
    try:
        T = robot.fk(q)
    except ValueError:  # a robot fk does not serve
        return 0.0
    if tip is not None:
        T = T[:, tip]
    if T.ndim == 4 and T.shape[:2] == P.shape[:2]:  # a tree: each tip turns with its own
        Pc = P - P.mean(axis=0)
        total = float(np.sum(Pc * Pc))
        if total <= 0:
            return 0.0
        left = 0.0
        for k in range(T.shape[1]):
            R = T[:, k, :3, :3]
            A, rhs = (R - R.mean(axis=0)).reshape(-1, 3), Pc[:, k].reshape(-1)
            u, *_ = np.linalg.lstsq(A, rhs, rcond=None)
            left += float(np.sum((rhs - A @ u) ** 2))
        return math.sqrt(left / total)
    R = T[:, :3, :3]
    if R.shape != (len(q), 3, 3):
        return 0.0
    A = (R - R.mean(axis=0)).reshape(-1, 3)  # (3N, 3)
    Pc = P - P.mean(axis=0)
    total = float(np.sum(Pc * Pc))
    if total <= 0:
        return 0.0
    rhs = np.swapaxes(Pc, 0, 1).reshape(P.shape[1], -1).T  # (3N, m)
    u, *_ = np.linalg.lstsq(A, rhs, rcond=None)
    return math.sqrt(float(np.sum((rhs - A @ u) ** 2)) / total)


def unmodelled_tool_possible(ratio: float, rotating: float) -> bool:
    """Whether a tool the robot file lacks could make the measured cloud `ratio` times
    the nominal one's size.

    Such a tool adds ``(R_i - mean R) t`` to the nominal points; matching ``ratio · P``
    needs ``(1 - ratio) P ≈ (R_i - mean R) t``, which leaves at least `rotating` ·
    |1 - ratio| of the nominal spread over, against a measured spread of `ratio` times
    it: possible only while that is within `TOOL_SLACK` · `SHAPE` of the measured spread.
    """
    return rotating * abs(1 - ratio) <= TOOL_SLACK * SHAPE * ratio


def check_positions(robot: Robot, q: np.ndarray, points: np.ndarray) -> PositionFinding | None:
    """The measured cloud against the nominal robot's at the same joint values.

    Parameters
    ----------
    robot : Robot
        The nominal robot.
    q : ndarray, shape (N, dof) or (N, dof + inputs)
        Joint values, SI.
    points : ndarray, shape (N, m, 3)
        Measured points, m (in any frame).

    Returns
    -------
    PositionFinding or None
        None when the clouds agree in size or cannot be compared (too few points, a
        nominal cloud that does not move).
    """
    q, points = _subsample(q, points)
    if points.shape[0] * points.shape[1] < MIN_POINTS:
        return None
    P = _nominal_points(robot, q, points.shape[1])
    if P is None:
        return None
    found = _compare(robot, q, P, points)
    if found is not None or not robot.is_tree:
        return found
    # one tip in another unit among tips in the right one: pooled, the others hide it
    for k, tip in enumerate(robot.tips):
        found = _compare(robot, q, P[:, [k]], points[:, [k]], tip=k)
        if found is not None:
            return dataclasses.replace(found, tip=tip)
    return None


def _compare(robot, q, P, points, tip=None) -> PositionFinding | None:
    """`check_positions` of the nominal cloud `P` and the measured `points` (N, m, 3)."""
    fit = similarity(P.reshape(-1, 3), points.reshape(-1, 3))
    if not fit.spread_nominal > 1e-6 or not fit.spread_measured > 0:
        return None
    ratio = fit.scale if fit.scale > 0 else fit.spread_measured / fit.spread_nominal
    far = abs(math.log(ratio)) > math.log(SCALE_REFUSED)
    copy = fit.shape_error <= SHAPE
    named = length_unit_slip(ratio) is not None
    if not far or not (copy or named):
        return None
    tool_could_explain = unmodelled_tool_possible(ratio, rotating_residual(robot, q, P, tip))
    refused = copy and not tool_could_explain
    return PositionFinding(ratio, fit.shape_error, tool_could_explain, refused)


def check_joints(
    robot: Robot, q: np.ndarray, points: np.ndarray, joints=None
) -> JointFinding | None:
    """Revolute joint values read in the other angle unit, if the measured points fit the
    robot only that way.

    Values of the `joints` (0-based indices of revolute joints; default all revolute) are
    tried as radians (× 180/π) when read so they stay within a turn either way, as happens
    only to degrees of a few units; values beyond a turn either way in radians are tried
    as degrees (× π/180). The declared reading is kept whenever it fits the measured
    points; the other one is refused only when it fits them and the declared one does not.

    Returns
    -------
    JointFinding or None
        None when the declared reading is the only plausible one.
    """
    q, points = _subsample(q, points)
    revolute = [i for i, j in enumerate(robot.controller_joints) if j.type == "R"]
    joints = revolute if joints is None else [i for i in joints if i in revolute]
    if not joints or points.shape[0] < MIN_POINTS:
        return None
    values = q[:, joints]
    largest = float(np.max(np.abs(values)))
    if np.ptp(values, axis=0).max() <= 0:
        return None
    if largest > 2 * math.pi + 1e-9:
        factor = math.pi / 180  # degrees given as radians
    else:
        factor = 180 / math.pi  # radians in degree columns
    other = q.copy()
    other[:, joints] *= factor
    # the other reading must be an angle a joint turns to (the fit below decides)
    if np.abs(other[:, joints]).max() > 2 * math.pi + 1e-9:
        return None
    m = points.shape[1]
    P, P_other = _nominal_points(robot, q, m), _nominal_points(robot, other, m)
    if P is None or P_other is None:
        return None
    y = points.reshape(-1, 3)
    spread = float(np.sqrt(np.mean(np.sum((y - y.mean(axis=0)) ** 2, axis=1))))
    rms, rms_other = rigid_rms(P.reshape(-1, 3), y), rigid_rms(P_other.reshape(-1, 3), y)
    if rms <= 0.5 * spread:
        return None  # the declared reading fits: tiny motions in the declared unit
    refused = rms_other <= 0.2 * rms
    return JointFinding(factor, rms, rms_other, largest, refused)


def _subsample(q: np.ndarray, points: np.ndarray):
    q = np.asarray(q, dtype=float)
    points = np.asarray(points, dtype=float).reshape(len(q), -1, 3)
    if len(q) > DOOR_POSES:
        index = np.linspace(0, len(q) - 1, DOOR_POSES).round().astype(int)
        q, points = q[index], points[index]
    return q, points


def position_text(found: PositionFinding, columns: str | None = None, declared="m") -> str:
    """What the position finding means, and the fix, for a CSV's `columns` (e.g.
    ``"x_mm, y_mm, z_mm"`` read in `declared` units) or, without them, for `Measurements`
    (metres)."""
    unit = length_unit_slip(found.ratio, declared)
    head = (
        f"the measured points span {ratio_text(found.ratio)} what the robot reaches at "
        "these joint values"
    )
    if columns is not None:
        if unit is not None:
            return (
                f"{head}: are {columns} in {_LENGTH_WORDS[unit]}? Convert them to "
                f"{_LENGTH_WORDS[declared]}, or name the columns for their unit "
                "(x, y, z in m; x_mm, y_mm, z_mm; x_um, y_um, z_um)"
            )
        return (
            f"{head}: check the unit of {columns} (and the robot file's length_unit), and "
            "that the file belongs to this robot"
        )
    if unit is not None:
        return (
            f"{head}: are the positions {api_unit_words(unit)}? Measurements take metres "
            "(in a CSV file: x, y, z in m or x_mm, y_mm, z_mm in mm)"
        )
    return (
        f"{head}: check the unit of the positions (Measurements take metres; in a CSV file "
        "x_mm, y_mm, z_mm columns take mm) and of the robot file's lengths"
    )


def joint_text(found: JointFinding, columns: str | None = None) -> str:
    """What the joint finding means, and the fix (`columns`: the CSV's joint columns)."""
    fit = (
        f"the measured points fit the robot only with these values read as "
        f"{'radians' if found.factor > 1 else 'degrees'} (rigid-fit RMS "
        f"{found.rms_other * 1e3:.3g} mm, against {found.rms_declared * 1e3:.3g} mm as given)"
    )
    if found.factor > 1:
        if columns is not None:
            return (
                f"{columns} hold degrees by their names, but every value lies within "
                f"±{math.degrees(found.largest):.3g}, and {fit}: they look like radians; "
                "convert them to degrees or rename them q1_rad, q2_rad, …"
            )
        return (
            f"the revolute joint values all lie within ±{found.largest:.3g} rad "
            f"(±{math.degrees(found.largest):.3g}°), and {fit}: were radians converted with "
            "numpy.deg2rad as if they were degrees? Measurements take radians"
        )
    where = f"{columns} hold radians by their names, but" if columns else "the joint values"
    return (
        f"{where} reach {found.largest:.4g}, more than two turns in radians, and {fit}: they "
        "look like degrees; Measurements take radians (numpy.deg2rad), a CSV file names "
        "degree columns q1_deg, q2_deg, …"
    )


def at_the_door(
    robot: Robot,
    q: np.ndarray,
    points: np.ndarray,
    *,
    label: str | None = None,
    position_columns: str | None = None,
    declared: str = "m",
    joint_columns: str | None = None,
    joints=None,
) -> None:
    """Refuse (`CalibrationError`) or warn (`CalibrationWarning`) about unit slips.

    Parameters
    ----------
    robot : Robot
        The nominal robot.
    q : ndarray, shape (N, dof)
        Joint values, SI as read.
    points : ndarray, shape (N, 3) or (N, m, 3)
        Measured points, m as read.
    label : str, optional
        The file, to start messages with.
    position_columns, declared : str, optional
        The CSV's position columns (``"x_mm, y_mm, z_mm"``) and the unit they declare.
    joint_columns : str, optional
        The CSV's joint columns that `joints` (0-based) are read from, e.g. the ``_deg``
        ones; without them, every revolute joint and wording for `Measurements`.
    """
    prefix = f"{label}: " if label else ""
    found = check_joints(robot, q, points, joints)
    if found is not None:
        text = prefix + joint_text(found, joint_columns)
        if found.refused:
            raise CalibrationError(text)
        warnings.warn(text, CalibrationWarning, stacklevel=3)
        return
    position = check_positions(robot, q, points)
    if position is None:
        return
    if position.tip is not None:  # one tip's columns, not all of them
        prefix += f"tip {position.tip!r}: "
        if position_columns is not None:
            position_columns = f"its columns ({position.tip}_x…)"
    text = prefix + position_text(position, position_columns, declared)
    if position.refused:
        raise CalibrationError(text)
    if position.tool_could_explain:
        text += (
            " (not refused: at these poses the robot's point only turns about one point, so "
            "a tool the robot file does not have could explain the size)"
        )
    warnings.warn(text, CalibrationWarning, stacklevel=3)


def distances_at_the_door(robot: Robot, q: np.ndarray, pairs: np.ndarray, distances) -> None:
    """Refuse distances (m) that are a scaled copy of the nominal robot's (1/1000: metres in
    a ``distance_mm`` column; 1/25.4: inches), as `at_the_door` does for points.

    Parameters
    ----------
    robot : Robot
    q : ndarray, shape (N, dof)
        Poses, SI.
    pairs : ndarray of int, shape (P, 2)
    distances : ndarray, shape (P,)
        Measured distances, m.
    """
    d = np.asarray(distances, dtype=float)
    P = _nominal_points(robot, q, 1)
    if P is None or len(d) < MIN_POINTS:
        return
    nominal = np.linalg.norm(P[pairs[:, 0], 0] - P[pairs[:, 1], 0], axis=1)
    scale2 = float(nominal @ nominal)
    if scale2 <= 0 or not np.any(d > 0):
        return
    ratio = float(d @ nominal) / scale2
    if not ratio > 0 or abs(math.log(ratio)) <= math.log(SCALE_REFUSED):
        return
    shape = float(np.linalg.norm(d - ratio * nominal) / np.linalg.norm(d))
    if shape > SHAPE:
        return
    head = (
        f"the measured distances are {ratio_text(ratio)} the nominal robot's between the same poses"
    ).replace(" of the", " the")
    in_file, in_code = length_unit_slip(ratio, "mm"), length_unit_slip(ratio, "m")
    text = (
        f"{head}: are the distance_mm values in {_LENGTH_WORDS[in_file]}?"
        if in_file is not None
        else f"{head}: check the unit of the distance_mm values (mm) and the robot file's"
    )
    text += " (DistanceMeasurements built in code take metres" + (
        f": are they {api_unit_words(in_code)}?)" if in_code is not None else ")"
    )
    if unmodelled_tool_possible(ratio, rotating_residual(robot, q, P)):
        warnings.warn(text, CalibrationWarning, stacklevel=3)
        return
    raise CalibrationError(text)
