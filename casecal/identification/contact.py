"""Calibration without a tracker: sessions that touch a fixed point or a plane.

A contact session is a session (`casecal.identification.sessions`) whose measurements are
known by construction in its own frame, so the one fit in rounds serves it unchanged:

- a **fixed point** (``"point"``; a sphere or cone the tool tip is held in, in many
  orientations): every pose's tip is at (0, 0, 0) in the session's frame. The session's
  base translation is where the point is (the robot's base seen from the point); its
  rotation is blind (turning about a point leaves it where it is) and is held at its
  start, the robot's nominal base rotation.
- a **plane** (``"plane"``; a touch probe touching an unknown plane): only the
  coordinate along the normal is measured, z = 0 in the session's frame; x and y carry
  σ = inf, weight 0. The session's frame is the plane's: its tilt (two rotations) and
  offset are estimated; the frame's own x, y and its rotation about the normal are blind
  and held at their start, a plane fitted through the nominal tips of the session.

Which robot parameters such data cannot see (one plane sees little: what moves the tip
within the plane is blind) is the rank's to say, as for any data. A blind frame
parameter is not estimated at all, rather than left to the rank: which of a fixed
point's rotation and translation the rank would keep is arbitrary, and words name it
here (`notes`).
"""

from __future__ import annotations

import numpy as np

from ..errors import CalibrationError
from ..model.frames import rotation_vector
from ..model.parameters import frame_names
from ..model.robot import Robot

MIN_PLANE_POSES = 4
"""A plane (three parameters) needs four touches at least, to leave one to check with."""

PLANE_SPREAD = 5e-3
"""RMS extent (m) of a plane's nominal tips along their second principal direction
below which they lie at one point or along a line: the plane's tilt is then undetermined."""

POINT_TURN = 0.05
"""RMS angle (rad, about 3°) of the tool's orientations about their mean below which a
fixed point was held in one orientation: the tool tip's offset is then undetermined. The
turns must spread so about two axes (their second principal RMS): turned about one axis
only, the offset along it is undetermined, and fits wandered along such directions."""

CONTACT_SPREAD = 0.1
"""RMS distance (m) of a session's nominal tips from their point (a fixed point) or from
their best plane (a plane) past which the joint values cannot be this robot's at one
point or plane: a robot's own errors move its tip millimetres, not decimetres."""

PLAUSIBLE_FACTOR = 2.0
"""A contact fit whose estimate of a joint parameter deviates by more than this many
times its plausible size (`casecal.model.parameters.facts_of`: 2.5 mm, 0.5° unless the
robot says otherwise) fails its audit (`plausibility_check`)."""

PLAUSIBLE_CHECK = "estimates a real robot could have"


def check_robot(robot: Robot, measurements) -> None:
    """Refuse what contact sessions do not support (yet)."""
    if robot.is_tree:
        raise CalibrationError(
            "contact sessions (a fixed point, a plane) are not supported for a kinematic tree "
            "yet; measure the tips with an instrument"
        )
    if robot.inputs:
        raise CalibrationError(
            "contact sessions (a fixed point, a plane) are not supported for a robot with "
            "inputs (load terms) yet"
        )
    if robot.points:
        raise CalibrationError(
            "contact sessions measure the tool tip alone; robot "
            f"{robot.name!r} has {len(robot.points)} measured points: give it none "
            "(the tool frame's origin is the tip)"
        )
    if measurements.orientations is not None:
        raise CalibrationError("contact sessions measure no orientation; give none")


def plausible_error(robot: Robot, names) -> float:
    """RMS error (m) across the joint ranges of a robot whose asked-for joint parameters
    deviate by their plausible sizes (`casecal.model.parameters.facts_of`), independently;
    0 without joint limits.

    A contact session's start residuals say little of the robot's error: where the point
    or the plane is absorbs most of it (a fixed point's poses differ by turns about it
    only). The fit then judges what the noise hides against this error instead, the size
    of what a calibration is for.
    """
    from ..design.poses import uniform
    from ..model import kinematics
    from ..model.parameters import facts_of

    joint = [n for n in names if not n.startswith(("base_", "tool_"))]
    try:
        q = uniform(robot, 200, seed=0)
    except CalibrationError:
        return 0.0
    if not joint:
        return 0.0
    chain = kinematics.chain(robot.structure)
    p = robot.vector()
    J = chain.evaluate("points_jacobian", q, p, chain.columns(joint), anchor=p)
    size = np.array([facts_of(n, robot.sizes).plausible for n in joint])
    per_point = np.sum((J * size) ** 2, axis=(1, 2)) / (J.shape[1] / 3)
    return float(np.sqrt(np.mean(per_point)))


def held_names(label: str, mark: str, kind: str, base_rpy) -> tuple[str, ...]:
    """The blind frame parameters of a contact session (module doc), held at their start.

    A plane's rotation about its normal is ``rz`` of its chart (`casecal.model.rotation_chart`)
    where the start's pitch is within 45° of 0, else ``rx``: the blind turn is
    ``(-sin p0, 0, cos p0)`` in (δroll, δpitch, δyaw), so holding the larger of its two
    components leaves the two estimated ones seeing the normal's tilt.
    """
    x, y, _, rx, ry, rz = frame_names("base", mark)
    if kind == "point":
        return (rx, ry, rz)
    pitch = float(base_rpy[1])
    return (x, y, rz if abs(np.cos(pitch)) >= abs(np.sin(pitch)) else rx)


def start_frame(robot: Robot, q_plain, model: np.ndarray, kind: str, label: str) -> np.ndarray:
    """The 4×4 transform from the nominal robot's frame (that of `model`) to the contact
    session's frame at the start, after checking the session's poses can determine it.

    Parameters
    ----------
    robot : Robot
        Nominal, without sessions.
    q_plain : ndarray, shape (n, dof)
        The session's joint values.
    model : ndarray, shape (n, 3)
        The nominal tips of the session's poses, m.
    """
    n = len(model)
    centre = model.mean(axis=0)
    out = np.eye(4)
    _check_spread(robot, q_plain, model - centre, kind, label)
    if kind == "point":
        turns = robot.fk(q_plain)[:, :3, :3]
        mean = _mean_rotation(turns)
        v = rotation_vector(turns @ mean.T)  # (n, 3), rad
        spread = float(np.sqrt(np.mean(np.sum(v**2, axis=1))))
        if spread < POINT_TURN:
            raise CalibrationError(
                f"fixed-point session {label!r}: the tool turns by {np.degrees(spread):.2g}° "
                f"RMS over its {n} poses: held in one orientation, a point tells nothing of "
                "the tool; hold the tip in the point in orientations tens of degrees apart "
                f"(tilted about two axes){_small_joints(robot, q_plain)}"
            )
        second = float(np.linalg.svd(v - v.mean(axis=0), compute_uv=False)[1] / np.sqrt(n))
        if second < POINT_TURN:
            raise CalibrationError(
                f"fixed-point session {label!r}: the tool turns about one axis only (about "
                f"any other by {np.degrees(second):.2g}° RMS over its {n} poses): the tip's "
                "offset along that axis, and the joint parameters that move it, are then "
                "undetermined; hold the tip in the point in orientations tilted about two "
                "axes, tens of degrees apart"
            )
        out[:3, 3] = -centre  # the mean nominal tip maps to 0
        return out
    if n < MIN_PLANE_POSES:
        raise CalibrationError(
            f"plane session {label!r} has {n} pose{'s' * (n != 1)}: a plane (its tilt and "
            f"offset) needs at least {MIN_PLANE_POSES} touches, and many more spread over "
            "it to be well determined"
        )
    _, s, Vt = np.linalg.svd(model - centre, full_matrices=False)
    spread = s[1] / np.sqrt(n)
    if spread < PLANE_SPREAD:
        raise CalibrationError(
            f"plane session {label!r}: its {n} touches lie within {spread * 1e3:.2g} mm of "
            "one point or one line (nominally), which leaves the plane's tilt undetermined; "
            "touch it at points spread over an area, tens of millimetres apart each way"
            f"{_small_joints(robot, q_plain)}"
        )
    normal = Vt[2]
    # deterministic: the normal toward the robot's base, the in-plane x from the axis of
    # the robot's frame least along the normal
    side = float(normal @ (robot.base.matrix()[:3, 3] - centre))
    if abs(side) > 1e-9:
        normal = normal * np.sign(side)
    elif normal[np.argmax(np.abs(normal))] < 0:
        normal = -normal
    axis = np.eye(3)[int(np.argmin(np.abs(normal)))]
    x = axis - (axis @ normal) * normal
    x /= np.linalg.norm(x)
    R = np.column_stack([x, np.cross(normal, x), normal])  # the plane's axes, robot frame
    out[:3, :3] = R.T
    out[:3, 3] = -R.T @ centre
    return out


def _check_spread(robot: Robot, q_plain, offsets: np.ndarray, kind: str, label: str) -> None:
    """Refuse a session whose nominal tips (`offsets` from their centre, (n, 3) m) are
    decimetres from one point or one plane (`CONTACT_SPREAD`): joint values in another
    unit, or of another robot."""
    if kind == "point":
        spread = float(np.sqrt(np.mean(np.sum(offsets**2, axis=1))))
        where = "the point they are held at"
    else:
        if len(offsets) < 3:
            return
        spread = float(np.linalg.svd(offsets, compute_uv=False)[2] / np.sqrt(len(offsets)))
        where = "the best plane through them"
    if spread <= CONTACT_SPREAD:
        return
    raise CalibrationError(
        f"{'fixed-point' if kind == 'point' else 'plane'} session {label!r}: at its joint "
        f"values the nominal robot's tip lies {spread * 1e3:.3g} mm RMS from {where}, "
        "where a robot's own errors move it millimetres: check the joint columns' unit "
        f"(degrees in q_rad columns?){_small_joints(robot, q_plain)} and that the file "
        "belongs to this robot"
    )


def _small_joints(robot: Robot, q_plain) -> str:
    """A hint when every revolute joint value is within ±π degrees: radians read as
    degrees look so."""
    revolute = [i for i, j in enumerate(robot.joints) if j.type == "R"]
    if revolute and np.all(np.abs(np.asarray(q_plain)[:, revolute]) <= np.radians(np.pi) + 1e-12):
        return "; every joint value is within ±3.2°, as radians in q_deg columns would be"
    return ""


def _mean_rotation(R: np.ndarray) -> np.ndarray:
    """The rotation nearest the mean of rotations `R` (n, 3, 3)."""
    U, _, Vt = np.linalg.svd(R.mean(axis=0))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    return U @ D @ Vt


def note(label: str, kind: str, held: tuple[str, ...], poses: int) -> str:
    """The words for what a contact session cannot see (the summary's notes)."""
    names = ", ".join(held)
    if kind == "point":
        return (
            f"Fixed point {label!r} ({poses} poses, the tool tip held in one point): the "
            "point's position is estimated (its session's base translation); the "
            "session's rotation is not observable (turning about a point leaves it where "
            f"it is) and was held at its start, the robot's nominal base rotation ({names})."
        )
    return (
        f"Plane {label!r} ({poses} touches, only the coordinate along its normal "
        "measured): the plane's own x, y and rotation about its normal are not observable "
        "(a plane fixes only its normal direction and offset); held at their start, a "
        f"plane fitted through the nominal tips ({names}). Its normal and offset are "
        "estimated; what of the robot moves the tip only within the plane it cannot see."
    )


def plausibility_check(nominal: Robot, fitted: Robot, estimated):
    """The audit line of a contact fit: its joint parameters' estimates within
    `PLAUSIBLE_FACTOR` times their plausible sizes.

    Contacts see the robot only through where its tip meets points and planes; at poses
    that leave a direction nearly unseen (a point held while turning about one axis, one
    plane), a fit can wander along it tens of millimetres and still explain the data as
    well as the truth does, and the prediction check, which measures the error before
    calibration by how far the fit moved, cannot tell. A tracker fit is not judged so:
    its data show the robot's error directly.
    """
    from ..model.parameters import facts_of
    from .audit import Check

    joint = [n for n in estimated if not n.startswith(("base_", "tool_")) and "@" not in n]
    moved = fitted.deviations_from(nominal, joint)
    far = []
    for name in joint:
        facts = facts_of(name, nominal.sizes)
        if abs(moved[name]) > PLAUSIBLE_FACTOR * facts.plausible:
            u = "°" if facts.shown == "deg" else f" {facts.shown}"  # as the rank's reasons
            shown = f"{name} {moved[name] * facts.factor:+.3g}{u}"
            far.append((abs(moved[name]) / facts.plausible, shown))
    if not far:
        return Check(
            PLAUSIBLE_CHECK,
            True,
            f"every joint parameter within {PLAUSIBLE_FACTOR:g}× its plausible size",
        )
    far.sort(reverse=True)
    shown = ", ".join(f"{text} ({ratio:.3g}× plausible)" for ratio, text in far[:4])
    more = f" and {len(far) - 4} more" if len(far) > 4 else ""
    return Check(
        PLAUSIBLE_CHECK,
        False,
        f"{shown}{more}: no real robot is that far from its nominal, and contacts (points, "
        "planes) leave directions these poses barely see, along which a fit wanders; tilt "
        "the tool about two axes at each point, touch planes facing three ways, or give the "
        "robot its own sizes (with_plausible) if its errors really are that large",
    )


def contact_checks(checks, nominal: Robot, fitted: Robot, estimated, alone: bool):
    """`checks` (an `Audit`) of a fit with contact sessions, with `plausibility_check`;
    with contacts `alone`, a failed size check leads, in words of what contacts cannot
    see (their points are 0: a robot shrunk to a point meets every one of them)."""
    import dataclasses

    from .audit import Audit

    plausible = plausibility_check(nominal, fitted, estimated)
    lines = [*checks.checks, plausible]
    size = [c for c in lines if c.name == "robot keeps its size" and c.passed is False]
    if alone and size:
        lead = dataclasses.replace(
            size[0],
            text=f"{size[0].text.split(',')[0]}: contacts (points, planes) alone cannot see "
            "the robot's size, since a robot shrunk toward a point meets every point and "
            "plane; leave out of the parameters a length you know (the tool's, or the last "
            "link's: e.g. without a6 and d6) so that it sets the size",
        )
        lines = [lead, *(c for c in lines if c is not size[0])]
    return Audit(tuple(lines))
