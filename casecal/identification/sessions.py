"""Measurements of several sessions, fitted together: one robot, an instrument frame each.

A calibration campaign spans sessions with the laser tracker (the instrument) re-mounted
between them, sometimes the probe too. The robot's parameters are the same in every
session; where the instrument stood is not. `casecal.identify` therefore fits, from
`Measurements.session`, one robot with a base frame per session (`Robot.sessions`): the
first session in order of appearance keeps ``base_x … base_rz`` (its frame is the
calibrated robot's base), every other session ``base_x@LABEL … base_rz@LABEL``, and with
``per_session=("base", "tool")`` a tool frame each as well (``tool_x@LABEL`` …).

The poses carry one indicator per later session (`casecal.model.kinematics`), so the one
graph, the one `Problem` and the one fit in rounds serve every session: the Jacobian
columns of a session's frame are exactly zero on the other sessions' poses, and the
covariance, the rank and the audit see all sessions at once. Each session's base starts
from a rigid fit of the nominal robot's points to that session's measured ones; the frames
are always estimated (where the instrument stood is no parameter one can know or hold).

Contact sessions (`Measurements.contact`: a fixed point, a plane; see
`casecal.identification.contact`) are sessions too, with their own start and the frame
parameters they cannot see held at it.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..data.measurements import Measurements
from ..errors import CalibrationError
from ..model.frames import rigid_fit, rpy_from_matrix
from ..model.parameters import FRAME_AXES, frame_names
from ..model.robot import Frame, Robot

MIN_SESSION_POSES = 3
"""A session's frame (six parameters) needs at least three measured poses."""


@dataclass(frozen=True)
class SessionFit:
    """One session's fitted frames (`Calibration.sessions`).

    Attributes
    ----------
    label : str
    base : Frame
        Where the instrument stood: the robot's base frame in this session's instrument
        frame, SI (m, rad).
    base_standard_errors : tuple of 6 float
        Of x, y, z (m) and of the rotation's deviations δroll, δpitch, δyaw (rad; the
        turns of `casecal.model.rotation_chart` about the fitted frame, which are the
        angles' own errors where the pitch is 0). NaN where a parameter was held.
    tool, tool_standard_errors : Frame or None, tuple or None
        The session's own tool frame and its errors, with ``per_session=("base", "tool")``.
    n_poses : int
    rms : float
        RMS position error of this session's measured points after calibration, m.
    names : tuple of str
        The parameters of this session's frames (``base_x@LABEL`` …; the first session's
        are ``base_x`` …).
    """

    label: str
    base: Frame
    base_standard_errors: tuple[float, ...]
    tool: Frame | None
    tool_standard_errors: tuple[float, ...] | None
    n_poses: int
    rms: float
    names: tuple[str, ...]
    kind: str = ""
    """``"point"`` or ``"plane"`` for a contact session, "" for measured points."""
    held: tuple[str, ...] = ()
    """The frame parameters a contact session cannot see, held at their start."""


@dataclass(frozen=True)
class Sessions:
    """How `identify` treats measurements of several sessions (None for one)."""

    labels: tuple[str, ...]
    index: np.ndarray  # (N,) each pose's session, 0 = the first
    frames: tuple[str, ...]  # the frames each session has of its own
    kinds: tuple[str, ...] = ()  # per label: "point", "plane" (contact) or ""

    def kind(self, k: int) -> str:
        """Session `k`'s contact kind, "" for measured points."""
        return self.kinds[k] if self.kinds else ""

    @property
    def indicators(self) -> np.ndarray:
        """(N, S - 1): 1 in the column of a pose's session, all 0 for the first session."""
        out = np.zeros((len(self.index), len(self.labels) - 1))
        later = self.index > 0
        out[np.flatnonzero(later), self.index[later] - 1] = 1.0
        return out

    def names(self) -> list[str]:
        """Every session's frame parameters, the first session's without a label."""
        return [
            n
            for k, label in enumerate(self.labels)
            for frame in self.frames
            for n in frame_names(frame, label if k else "")
        ]


def resolve(robot: Robot, measurements: Measurements, per_session) -> Sessions | None:
    """The sessions of `measurements` (None for one), `per_session` checked.

    `per_session` None: the frames `robot` has per session already (a `Calibration`'s
    nominal robot), else only the base.
    """
    if per_session is None:
        per_session = robot.session_frames or ("base",)
    if isinstance(per_session, str):
        per_session = (per_session,)
    try:
        frames = tuple(per_session)
    except TypeError:
        frames = (per_session,)
    texts = all(isinstance(f, str) for f in frames)
    if not texts or set(frames) not in ({"base"}, {"base", "tool"}):
        raise CalibrationError(
            f"per_session={per_session!r}: give ('base',) or ('base', 'tool'); each session "
            "has its own base frame (where the instrument stood), and its own tool frame "
            "too only when the probe was re-mounted"
        )
    frames = ("base", "tool") if "tool" in frames else ("base",)
    labels = measurements.sessions
    contact = measurements.contact or {}
    if contact and "tool" in frames:
        raise CalibrationError(
            "per_session=('base', 'tool') with contact sessions (a fixed point, a plane) is "
            "not supported: a contact cannot tell a re-mounted probe from the point or the "
            "plane; fit with per_session=('base',)"
        )
    if len(labels) < 2 and not contact:
        return None
    index = np.unique(measurements.session, return_inverse=True)[1]
    order = np.array([labels.index(v) for v in np.unique(measurements.session)])
    index = order[index]
    counts = np.bincount(index, minlength=len(labels))
    kinds = tuple(contact.get(label, "") for label in labels) if contact else ()
    few = [
        (labels[k], int(c))
        for k, c in enumerate(counts)
        if c < MIN_SESSION_POSES and (not kinds or kinds[k] != "plane")  # a plane: its own
    ]
    if few:
        label, count = few[0]
        raise CalibrationError(
            f"session {label!r} has {count} pose{'s' * (count != 1)}: its own frame (six "
            f"parameters) needs at least {MIN_SESSION_POSES}, and many more to be "
            "well determined; measure more poses in it, or join it to another session"
        )
    return Sessions(labels, index, frames, kinds)


def session_robot(robot: Robot, sessions: Sessions | None) -> Robot:
    """`robot` with a frame per later session (its own base and tool to start), or
    without sessions for one."""
    plain = dataclasses.replace(robot, sessions=(), auto_beta=False) if robot.sessions else robot
    if sessions is None:
        return plain
    return plain.with_sessions(sessions.labels[1:], sessions.frames)


def with_indicators(robot: Robot, q: np.ndarray, sessions: Sessions) -> np.ndarray:
    """`q` (N, dof or dof + inputs) followed by the session indicators (`Robot.sessions`),
    the inputs' reference values filled in where `q` has none."""
    if robot.inputs and q.shape[1] == robot.dof:
        reference = [value for _, value in robot.inputs]
        q = np.hstack([q, np.broadcast_to(reference, (q.shape[0], len(reference)))])
    return np.ascontiguousarray(np.hstack([q, sessions.indicators]))


def door(robot: Robot, measurements: Measurements, sessions: Sessions, check) -> None:
    """Run the unit checks at the door (`check(robot, measurements)`) on each session's
    own poses: a rigid fit of all sessions at once would see the instruments' moves.
    Contact sessions measured no points to check."""
    for k in range(len(sessions.labels)):
        if not sessions.kind(k):
            check(robot, measurements.take(sessions.index == k))


def start(robot: Robot, q, y, w, sessions: Sessions) -> tuple[Robot, str]:
    """`robot` (with sessions) with every session's base from a rigid fit of the nominal
    points to that session's measured ones, and a note for the summary.

    Parameters
    ----------
    robot : Robot
        With `sessions`' frames, all at the nominal base (`session_robot`).
    q : ndarray, shape (N, n_inputs)
        With the session indicators.
    y : ndarray, shape (N, m, 3)
        Measured points, m.
    w : ndarray, shape (N, 3)
        Position weights 1/σ.
    """
    from . import contact

    model = robot.measured_points(q)  # every session's frames nominal: the same robot
    values = {}
    notes = []
    plain = session_robot(robot, None)
    for k, label in enumerate(sessions.labels):
        rows = sessions.index == k
        kind = sessions.kind(k)
        if kind:  # nothing measured to fit to: the point or the plane through the tips
            fit = contact.start_frame(plain, q[rows, : robot.dof], model[rows, 0], kind, label)
        else:
            weights = np.repeat(np.mean(w[rows] ** 2, axis=1), y.shape[1])
            R, t = rigid_fit(model[rows].reshape(-1, 3), y[rows].reshape(-1, 3), weights=weights)
            fit = np.eye(4)
            fit[:3, :3], fit[:3, 3] = R, t
        base = fit @ robot.base.matrix()
        frame = [*base[:3, 3].tolist(), *rpy_from_matrix(base[:3, :3])]
        values.update(zip(frame_names("base", label if k else ""), frame, strict=True))
        if kind:
            held = contact.held_names(label, label if k else "", kind, frame[3:])
            notes.append(contact.note(label, kind, held, int(rows.sum())))
    counts = np.bincount(sessions.index, minlength=len(sessions.labels))
    shown = ", ".join(f"{label}: {c}" for label, c in zip(sessions.labels, counts, strict=True))
    own = "a base frame" if sessions.frames == ("base",) else "a base and a tool frame"
    first = sessions.labels[0]
    note = (
        f"The poses come from {len(sessions.labels)} sessions ({shown} poses): one robot was "
        f"fitted to all of them, with {own} per session, estimated whatever the parameters "
        f"asked for (the instrument was re-mounted). Session {first!r}, the first, keeps "
        f"the plain names (base_x …) and its frame is the calibrated robot's; the others' "
        f"are named base_x@LABEL …. Each base started from a rigid fit of the nominal "
        "positions to that session's measured points."
    )
    if sessions.kinds:
        note = (
            f"The poses come from {len(sessions.labels)} session"
            f"{'s' * (len(sessions.labels) > 1)} ({shown} poses), contacts among them: one "
            "robot was fitted to all of them, with a base frame per session (the first's, "
            f"{first!r}, keeps the plain names base_x … and is the calibrated robot's; the "
            "others' are base_x@LABEL …). A session of measured points started from a rigid "
            "fit of the nominal positions to its points, a fixed point at the mean nominal "
            "tip, a plane from one fitted through its nominal tips. " + " ".join(notes)
        )
        if all(sessions.kinds):
            note += (
                " Contacts alone see no length scale (a robot twice the size touches "
                "planes and points twice as far away just as well): the robot's size "
                "rests on the lengths not estimated (the tool's, as given); freeing all of "
                "them leaves it undetermined. Add a session of measured points, or keep "
                "the tool's lengths known."
            )
    return robot.with_parameters(values), note


def contact_held(robot: Robot, sessions: Sessions | None) -> list[str]:
    """The frame parameters the contact sessions cannot see (held at their start), for
    `robot` with every session's start frame."""
    from . import contact

    if sessions is None or not sessions.kinds:
        return []
    by_label = {s.label: s for s in robot.sessions}
    out = []
    for k, label in enumerate(sessions.labels):
        kind = sessions.kind(k)
        if kind:
            base = by_label[label].base if k else robot.base
            out.extend(contact.held_names(label, label if k else "", kind, base.rpy))
    return out


def fitted(
    calibrated: Robot, standard_errors: dict, residuals, sessions: Sessions, held=()
) -> dict:
    """`Calibration.sessions`: label -> `SessionFit`, in order of appearance.

    Parameters
    ----------
    calibrated : Robot
        The fitted robot, with its sessions.
    standard_errors : dict
        Of every asked-for parameter, SI.
    residuals : ndarray, shape (N, m, 3)
        After calibration, m (0 where not measured).
    held : sequence of str
        The contact sessions' frame parameters held at their start (`contact_held`).
    """
    out = {}
    by_label = {s.label: s for s in calibrated.sessions}
    for k, label in enumerate(sessions.labels):
        mark = label if k else ""
        if k:
            base, tool = by_label[label].base, by_label[label].tool
        else:
            base, tool = calibrated.base, calibrated.tool if "tool" in sessions.frames else None
        rows = sessions.index == k
        e = residuals[rows].reshape(-1, 3)

        def errors(frame, mark=mark):
            names = frame_names(frame, mark)
            return tuple(float(standard_errors.get(n, np.nan)) for n in names)

        names = tuple(n for f in sessions.frames for n in frame_names(f, mark))
        out[label] = SessionFit(
            label=label,
            base=base,
            base_standard_errors=errors("base"),
            tool=tool,
            tool_standard_errors=errors("tool") if tool is not None else None,
            n_poses=int(rows.sum()),
            rms=float(np.sqrt(np.mean(np.sum(e**2, axis=1)))),
            names=names,
            kind=sessions.kind(k),
            held=tuple(n for n in names if n in held),
        )
    return out


def table_text(fits: dict) -> str:
    """The sessions' fitted frames in mm and degrees, each value ± its standard error."""
    units = [f"{a}_{'mm' if len(a) == 1 else 'deg'}" for a in FRAME_AXES]
    head = ["session", "poses", "frame", *units, "rms_mm"]
    rows = [head]
    for fit in fits.values():
        frames = [("base", fit.base, fit.base_standard_errors)]
        if fit.tool is not None:
            frames.append(("tool", fit.tool, fit.tool_standard_errors))
        for i, (what, frame, se) in enumerate(frames):
            values = [*np.multiply(frame.xyz, 1e3), *np.degrees(frame.rpy)]
            errs = [*np.multiply(se[:3], 1e3), *np.degrees(se[3:])]
            cells = [_pm(v, e) for v, e in zip(values, errs, strict=True)]
            first = i == 0
            rows.append(
                [
                    fit.label if first else "",
                    str(fit.n_poses) if first else "",
                    what,
                    *cells,
                    f"{fit.rms * 1e3:.4f}" if first else "",
                ]
            )
    widths = [max(len(r[i]) for r in rows) for i in range(len(head))]
    lines = []
    for k, r in enumerate(rows):
        line = "  ".join(
            c.ljust(w) if i in (0, 2) else c.rjust(w)
            for i, (c, w) in enumerate(zip(r, widths, strict=True))
        )
        lines.append(line.rstrip())
        if k == 0:
            lines.append("-" * len(line))
    return "\n".join(lines)


def _pm(value: float, error: float) -> str:
    if not np.isfinite(error):
        return f"{value:.4f} (held)"
    return f"{value:.4f} ± {error:.4f}"
