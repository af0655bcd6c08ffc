"""Measurement CSV files: `read_csv` and `write_csv`, with units in the column names.

One row per pose. Columns (any order; extra columns are kept out of the way and ignored):

- joints ``q1`` … ``qn`` in rad (revolute) or m (prismatic), or with the unit in the
  name: ``q1_deg``, ``q1_rad``, ``q3_mm``, ``q3_m``; with a joint coupling
  (`casecal.Robot.coupling`) the controller's joints, the coupling's columns in order;
- measured position ``x, y, z`` in m, or ``x_mm, y_mm, z_mm``;
- several reflectors per pose instead: ``p1_x_mm, p1_y_mm, p1_z_mm, p2_x_mm, …``;
- a kinematic tree's tips (`casecal.model.tree`) instead: one point per tip, named after
  its link, ``right_marker_x_mm, right_marker_y_mm, right_marker_z_mm, left_marker_x_mm,
  …`` (or ``_m``); joints ``q1`` … in the tree's joint order. Every tip is measured at
  every pose for now: an empty cell in a tip's column is refused with its row;
- optional tool orientation as a unit quaternion ``qw, qx, qy, qz`` (tool frame in the
  measurement frame);
- optional noise σ: ``sigma`` (m) or ``sigma_mm``, one isotropic value per row, or per
  axis ``sigma_x_mm`` … ``sigma_z_mm``;
- optional ``session``: a label per row naming the measurement session (the instrument
  re-mounted between sessions; `casecal.identify` fits a base frame per session), any
  text of letters, digits, ``_`` and ``-`` (read as text: ``1`` and ``01`` differ);
- optional ``contact`` (with ``session``): ``point`` on the rows of a session whose tool
  tip was held in one fixed point, ``plane`` on those of a session touching one plane,
  empty on rows of measured points; one kind per session
  (`casecal.identification.contact`). A contact row has no measured position: its x, y, z
  cells are empty (the columns may be left out when every row is a contact); its ``sigma``
  is the contact's repeatability (a plane's x and y are not measured: σ inf).

Every mistake raises `CalibrationError` naming the file, the row or column, and the fix.
"""

from __future__ import annotations

import math
import re
import warnings

import numpy as np
import pandas as pd

from ..errors import CalibrationError, CalibrationWarning
from ..model.frames import matrix_from_quaternion, quaternion_from_matrix
from ..model.parameters import check_session_label
from ..model.robot import Robot
from ..textio import read_text, write_atomic, write_together  # noqa: F401 (re-export)
from .measurements import Measurements
from .table import read_table, too_big
from .units import at_the_door

_SCALE = {"": 1.0, "m": 1.0, "mm": 1e-3, "um": 1e-6, "rad": 1.0, "deg": math.pi / 180.0}
_JOINT = re.compile(r"^q(\d+)(?:_(deg|rad|mm|m))?$")


def read_csv(path, robot: Robot) -> Measurements:
    """Read measurements of `robot` from a CSV file (format in the module doc).

    The file must be UTF-8 text; a line starting with ``#`` is refused, naming its line
    (CSV has no comments, and skipping lines would shift every row number a message
    gives). Reading takes at most 3 times the file's size in memory (`read_table`); a file
    too large is one error saying how many rows would fit.

    Parameters
    ----------
    path : str or path
    robot : Robot
        The robot the data come from (its joint count and types decide the columns).

    Returns
    -------
    Measurements
        SI units.
    """
    try:
        return _read_csv(path, robot)
    except MemoryError:
        pass  # out of the except clause, the traceback's arrays are freed: then measure
    raise CalibrationError(too_big(path, "standard input" if str(path) == "-" else str(path)))


def _read_csv(path, robot: Robot) -> Measurements:
    df, label = read_table(path)
    columns = list(df.columns)
    q = read_joints(df, robot, label)
    if robot.inputs:
        q = np.column_stack([q, _inputs(df, robot, label)])
    session = _session(df, label)
    contact, touch = _contact(df, session, label)
    if robot.is_tree:
        y, named = _tip_positions(df, robot, label)
        in_metres = not any(re.search(r"_(mm|m|um)$", c) for c in named)
    else:
        y = _positions(df, columns, label, touch)
        in_metres = not any(re.fullmatch(r"(p\d+_)?[xyz]_(mm|m|um)", c) for c in columns)
        named = None
    # each session in its own instrument frame: the unit checks look at one at a time;
    # contact sessions measured no points to check
    groups = [slice(None)] if session is None else [session == s for s in dict.fromkeys(session)]
    groups = [rows for rows in groups if touch is None or not np.any(touch[rows])]
    for rows in groups:
        if in_metres:
            _check_metres(y[rows], robot, label)
        _check_units(df, robot, q[rows], y[rows], label, named)
    orientations = _orientations(df, columns, label)
    sigma = np.zeros((len(df), 3))
    if any(c in df for c in ("sigma", "sigma_m", "sigma_mm", "sigma_um")):
        name, scale = _pick(df, label, ["sigma"], None)
        sigma[:] = (_numbers(df, name, label) * scale)[:, None]
    elif any(re.fullmatch(r"sigma_[xyz](_(mm|m|um))?", c) for c in columns):
        for k, axis in enumerate("xyz"):
            name, scale = _pick(df, label, [f"sigma_{axis}"], None)
            sigma[:, k] = _numbers(df, name, label) * scale
    if np.any(sigma < 0):
        row = int(np.argwhere(sigma < 0)[0][0])
        raise CalibrationError(f"{label}: row {row + 2}: sigma is negative; it must be >= 0")
    return Measurements(
        q=q,
        positions=y,
        sigma=sigma,
        orientations=orientations,
        session=session,
        contact=contact,
    )


CONTACT_COLUMN = "contact"


def _contact(df: pd.DataFrame, session, label: str):
    """The ``contact`` column as (label -> kind, or None; (N,) bool: contact rows, or None)."""
    if CONTACT_COLUMN not in df:
        return None, None
    if session is None:
        raise CalibrationError(
            f"{label}: column 'contact' needs a 'session' column: each fixed point or plane "
            "is a session of its own"
        )
    values = df[CONTACT_COLUMN].astype(str).str.strip().str.lower()
    values = values.where(~values.isin(_GAPS), "").to_numpy(dtype=str)
    kinds = {}
    for row, (text, where) in enumerate(zip(values, session, strict=True)):
        if text not in ("", "point", "plane"):
            raise CalibrationError(
                f"{label}: row {row + 2}, column 'contact': {text!r}; give 'point' (a fixed "
                "point), 'plane' (a plane touched), or leave it empty (measured points)"
            )
        if kinds.setdefault(where, text) != text:
            raise CalibrationError(
                f"{label}: row {row + 2}: session {where!r} is {kinds[where] or 'measured'} "
                f"on earlier rows and {text or 'measured'} here; give a session one kind"
            )
    touch = values != ""
    return {k: v for k, v in kinds.items() if v} or None, touch


def _session(df: pd.DataFrame, label: str) -> np.ndarray | None:
    """The ``session`` column's labels (surrounding spaces dropped), or None without one;
    a blank cell or a label that cannot name parameters is refused with its row."""
    if "session" not in df:
        return None
    values = df["session"].astype(str).str.strip().to_numpy(dtype=str)
    blank = np.flatnonzero(values == "")
    if blank.size:
        raise CalibrationError(
            f"{label}: row {blank[0] + 2}, column 'session' is blank; give every row its "
            "session's label, or remove the column if all rows are of one session"
        )
    labels, first = np.unique(values, return_index=True)
    for text, row in sorted(zip(labels.tolist(), first.tolist(), strict=True), key=lambda t: t[1]):
        check_session_label(text, f"{label}: row {row + 2}, column 'session'")
    return values


def _inputs(df: pd.DataFrame, robot: Robot, label: str) -> np.ndarray:
    """The robot's per-pose inputs (`Robot.inputs`), from columns of the same names; a
    missing column takes the reference value, with a warning."""
    out = np.empty((len(df), len(robot.inputs)))
    for k, (name, reference) in enumerate(robot.inputs):
        if name in df:
            out[:, k] = _numbers(df, name, label)
        else:
            warnings.warn(
                f"{label}: no column {name!r}; every pose takes its reference value {reference:g}",
                stacklevel=3,
            )
            out[:, k] = reference
    return out


def _warn_outside_limits(q: np.ndarray, robot: Robot, label: str) -> None:
    for i, joint in enumerate(robot.controller_joints):
        if joint.limits is None:
            continue
        lo, hi = joint.limits
        slack = 1e-9 * max(1.0, abs(lo), abs(hi))
        rows = np.flatnonzero((q[:, i] < lo - slack) | (q[:, i] > hi + slack))
        if rows.size:
            warnings.warn(
                f"{label}: joint {i + 1} is outside its limits in {rows.size} rows (first: "
                f"row {rows[0] + 2}); check the joint zero and units, or the robot's limits",
                CalibrationWarning,
                stacklevel=3,
            )


MM_MARGIN = 10.0
"""Measured points spread over more than this many times the robot's largest possible
span (twice its reach) cannot be metres: they are millimetres read as metres."""

_POINT = re.compile(r"^p(\d+)_([xyz])(?:_(mm|m|um))?$")


def _check_metres(y: np.ndarray, robot: Robot, label: str) -> None:
    """Refuse positions in bare columns (metres) that only make sense as millimetres.

    Wherever the instrument stands, the measured points of one robot lie within twice its
    reach of each other (`Robot.reach`); points a thousand times farther apart are
    millimetres read as metres.
    """
    reach = robot.reach
    if reach is None or reach <= 0:
        return
    points = y.reshape(-1, 3)
    span = float(np.max(np.ptp(points, axis=0)))
    if span > MM_MARGIN * 2 * reach:
        raise CalibrationError(
            f"{label}: the measured points span {span:.4g} in the x, y, z columns, which are "
            f"metres, but {robot.name!r} reaches at most {reach:.3g} m from its base: they "
            "look like millimetres; name the columns x_mm, y_mm, z_mm (or p1_x_mm, …)"
        )


def _check_units(
    df: pd.DataFrame, robot: Robot, q: np.ndarray, y: np.ndarray, label: str, named=None
):
    """The door check of `casecal.data.units`, worded with this file's column names (the
    position columns `named`, when given: a tree's tips')."""
    if named:
        names = named
        found = re.search(r"_(mm|m|um)$", names[0])
        unit = found.group(1) if found else "m"
    else:
        names = [c for c in df.columns if _POINT.match(c) or re.fullmatch(r"[xyz](_(mm|m|um))?", c)]
        unit = re.fullmatch(r"(?:p\d+_)?[xyz](?:_(mm|m|um))?", names[0]).group(1) or "m"
    shown = ", ".join(names) if len(names) <= 3 else f"{names[0]}, {names[1]}, … {names[-1]}"
    revolute = [i for i, j in enumerate(robot.controller_joints) if j.type == "R"]
    in_degrees = [i for i in revolute if f"q{i + 1}_deg" in df]
    joints = in_degrees or revolute
    joint_names = [f"q{i + 1}_deg" if in_degrees else _joint_column(df, i) for i in joints]
    at_the_door(
        robot,
        q,
        y,
        label=label,
        position_columns=shown,
        declared=unit,
        joint_columns=_listed(joint_names),
        joints=joints,
    )


def _joint_column(df: pd.DataFrame, i: int) -> str:
    return f"q{i + 1}_rad" if f"q{i + 1}_rad" in df else f"q{i + 1}"


def _listed(names: list[str]) -> str:
    if len(names) <= 3:
        return ", ".join(names)
    return f"{names[0]} … {names[-1]}"


def _positions(df: pd.DataFrame, columns, label: str, touch=None) -> np.ndarray:
    """x, y, z -> (N, 3); or p1_x … pm_z (several reflectors) -> (N, m, 3), in m.

    `touch`: the rows of contact sessions (N,) bool, whose cells are empty (NaN here).
    """
    numbered = sorted({int(m.group(1)) for c in columns if (m := _POINT.match(c))})
    if touch is not None and np.any(touch) and numbered:
        raise CalibrationError(
            f"{label}: contact sessions measure one point per pose; give x, y, z columns "
            "(or none, when every row is a contact), not numbered points"
        )
    if not numbered:
        y = np.full((len(df), 3), np.nan)
        plain = [c for c in columns if re.fullmatch(r"[xyz](_(mm|m|um))?", c)]
        if touch is not None and np.all(touch) and not plain:
            return y  # contacts only: nothing measured to read
        for k, axis in enumerate("xyz"):
            name, scale = _pick(df, label, [axis], None)
            if touch is None or not np.any(touch):
                y[:, k] = _numbers(df, name, label) * scale
            else:
                _contact_cells(df, name, label, touch)
                values = pd.to_numeric(df[name].astype(str).str.strip(), errors="coerce")
                values = values.to_numpy(dtype=float)
                bad = ~np.isfinite(values) & ~touch
                if bad.any():
                    row = int(np.flatnonzero(bad)[0])
                    raise CalibrationError(
                        f"{label}: row {row + 2}, column {name!r}: "
                        f"{str(df[name].iloc[row])!r} is not a finite number; a row of "
                        "measured points needs its position (fix or remove that row)"
                    )
                y[~touch, k] = values[~touch] * scale
        return y
    plain = [c for c in columns if re.fullmatch(r"[xyz](_(mm|m|um))?", c)]
    if plain:
        raise CalibrationError(
            f"{label}: both {plain[0]!r} and numbered points (p1_x…) are given; use one form"
        )
    if numbered != list(range(1, len(numbered) + 1)):
        raise CalibrationError(
            f"{label}: measured points are numbered {numbered}; number them p1, p2, … without gaps"
        )
    y = np.empty((len(df), len(numbered), 3))
    for j in numbered:
        for k, axis in enumerate("xyz"):
            name, scale = _pick(df, label, [f"p{j}_{axis}"], None)
            y[:, j - 1, k] = _numbers(df, name, label) * scale
    return y


def _contact_cells(df: pd.DataFrame, column: str, label: str, touch) -> None:
    """Refuse a contact row with a position in `column` (its cells are empty or 0)."""
    values = pd.to_numeric(df.loc[touch, column].astype(str).str.strip(), errors="coerce")
    given = values.to_numpy(dtype=float)
    bad = np.isfinite(given) & (given != 0)
    text = df.loc[touch, column].astype(str).str.strip().str.lower()
    bad |= ~np.isfinite(given) & ~text.isin(_GAPS).to_numpy()
    if bad.any():
        row = int(np.flatnonzero(touch)[np.flatnonzero(bad)[0]])
        raise CalibrationError(
            f"{label}: row {row + 2}, column {column!r}: a contact row (a fixed point or a "
            "plane) has no measured position; leave its x, y, z cells empty"
        )


_GAPS = ("", "nan", "na", "n/a", "null", "none", "-")
"""Cells that say a marker was not seen (lower case)."""


def _tip_positions(df: pd.DataFrame, robot: Robot, label: str) -> tuple[np.ndarray, list[str]]:
    """A tree's tips' columns ``{tip}_x`` … (any length unit) -> (N, tips, 3), m, and the
    columns' names."""
    y = np.empty((len(df), len(robot.tips), 3))
    named = []
    for j, tip in enumerate(robot.tips):
        for k, axis in enumerate("xyz"):
            name, scale = _pick(df, label, [f"{tip}_{axis}"], None)
            col = df[name]
            if col.dtype.kind in "iuf":
                gaps = np.isnan(col.to_numpy(dtype=float))
            else:
                gaps = col.astype(str).str.strip().str.lower().isin(_GAPS).to_numpy()
            if gaps.any():
                first, n = int(np.flatnonzero(gaps)[0]), int(gaps.sum())
                raise CalibrationError(
                    f"{label}: row {first + 2}, column {name!r} is empty: tip {tip!r} was not "
                    f"measured at that pose ({n} row{'s' if n > 1 else ''} like it); every tip "
                    "must be measured at every pose for now (gaps per marker are not "
                    "supported yet): remove those rows"
                )
            values = _numbers(df, name, label)
            y[:, j, k] = values * scale
            named.append(name)
    return y, named


def _orientations(df: pd.DataFrame, columns, label: str) -> np.ndarray | None:
    """qw, qx, qy, qz (unit quaternion of the tool frame) -> (N, 3, 3), or None."""
    names = ("qw", "qx", "qy", "qz")
    present = [c for c in names if c in columns]
    if not present:
        return None
    if len(present) != 4:
        missing = [c for c in names if c not in columns]
        raise CalibrationError(f"{label}: orientation needs qw, qx, qy, qz; missing {missing}")
    quat = np.column_stack([_numbers(df, c, label) for c in names])
    norm = np.linalg.norm(quat, axis=1)
    bad = np.flatnonzero(np.abs(norm - 1) > 1e-3)
    if bad.size:
        raise CalibrationError(
            f"{label}: row {bad[0] + 2}: quaternion (qw, qx, qy, qz) has norm {norm[bad[0]]:.4g}; "
            "it must be a unit quaternion"
        )
    return matrix_from_quaternion(quat / norm[:, None])


def read_joints(df: pd.DataFrame, robot: Robot, label: str) -> np.ndarray:
    """The joint columns of `df` for `robot`, in SI, shape (N, dof); warns outside limits."""
    columns = list(df.columns)
    q = np.empty((len(df), robot.dof))
    for i, joint in enumerate(robot.controller_joints, start=1):
        name, scale = _pick(df, label, [f"q{i}"], joint)
        q[:, i - 1] = _numbers(df, name, label) * scale
        if name in (f"q{i}", f"q{i}_rad", f"q{i}_m"):
            _check_joint_unit(q[:, i - 1], joint, name, label)
    extra = [c for c in columns if (m := _JOINT.match(c)) and int(m.group(1)) > robot.dof]
    if extra:
        raise CalibrationError(
            f"{label}: column {extra[0]!r} but robot {robot.name!r} has {robot.dof} joints; "
            "use the robot the data came from"
        )
    _warn_outside_limits(q, robot, label)
    return q


def _check_joint_unit(values: np.ndarray, joint, name: str, label: str) -> None:
    """Refuse joint columns in rad or m (bare or named so) whose values only make sense as
    deg or mm.

    A revolute joint's values beyond two turns (or, with limits, beyond twice its range and
    a full turn) are degrees; a prismatic joint's beyond ten times its travel, millimetres.
    """
    largest = float(np.max(np.abs(values)))
    base = name.split("_")[0]
    if joint.type == "R":
        span = max((abs(v) for v in joint.limits), default=np.pi) if joint.limits else np.pi
        if largest > max(2 * span, 2 * np.pi) + 1e-9:
            raise CalibrationError(
                f"{label}: column {name!r} (radians) reaches {largest:.4g}, more than this "
                f"revolute joint turns: the values look like degrees; name it {base}_deg"
            )
    elif joint.limits is not None:
        travel = max(abs(v) for v in joint.limits)
        if travel > 0 and largest > 10 * travel:
            raise CalibrationError(
                f"{label}: column {name!r} (metres) reaches {largest:.4g}, more than ten times "
                f"this prismatic joint's travel ({travel:.3g} m): the values look like "
                f"millimetres; name it {base}_mm"
            )


def joint_columns(q: np.ndarray, robot: Robot) -> dict:
    """The joint columns a measurement file is written with: ``q{i}_deg`` for a revolute
    joint, ``q{i}_mm`` for a prismatic one, from `q` (N, ≥ dof) in rad and m."""
    data = {}
    for i, joint in enumerate(robot.controller_joints, start=1):
        if joint.type == "R":
            data[f"q{i}_deg"] = np.rad2deg(q[:, i - 1])
        else:
            data[f"q{i}_mm"] = q[:, i - 1] * 1e3
    return data


def write_csv(path, measurements: Measurements, robot: Robot) -> None:
    """Write `measurements` as CSV in degrees and millimetres, atomically.

    Numbers are written with 17 significant digits, so reading back loses nothing but the
    rounding of the mm/deg conversion (~1e-16 relative).
    """
    data = joint_columns(measurements.q, robot)
    if measurements.q.shape[1] > robot.dof:
        for k, (name, _) in enumerate(robot.inputs):
            data[name] = measurements.q[:, robot.dof + k]
    points = measurements.points
    if robot.is_tree:
        if points.shape[1] != len(robot.tips):
            raise CalibrationError(
                f"the measurements have {points.shape[1]} points per pose but robot "
                f"{robot.name!r} is a tree with {len(robot.tips)} tips; write the "
                "measurements of this robot"
            )
        for j, tip in enumerate(robot.tips):
            for k, axis in enumerate("xyz"):
                data[f"{tip}_{axis}_mm"] = points[:, j, k] * 1e3
    elif measurements.positions.ndim == 2:
        touch = _contact_rows(measurements)
        for k, axis in enumerate("xyz"):
            column = points[:, 0, k] * 1e3
            if touch is not None:  # a contact row has no measured position: empty cells
                column = np.where(touch, np.nan, column)
            data[f"{axis}_mm"] = column
    else:
        for j in range(points.shape[1]):
            for k, axis in enumerate("xyz"):
                data[f"p{j + 1}_{axis}_mm"] = points[:, j, k] * 1e3
    if measurements.orientations is not None:
        quat = quaternion_from_matrix(measurements.orientations)
        for k, c in enumerate(("qw", "qx", "qy", "qz")):
            data[c] = quat[:, k]
    sigma = measurements.sigma
    if measurements.contact:  # a plane's x, y not measured (inf): its σ is its z's
        sigma = np.where(np.isinf(sigma), sigma[:, 2:3], sigma)
    if not np.all(np.isfinite(sigma)):
        raise CalibrationError(
            "some coordinates were not measured (sigma inf) outside contact sessions; the "
            "CSV format has no cell for that yet: write contact sessions, or every coordinate"
        )
    if np.any(sigma > 0):
        if np.all(sigma == sigma[:, :1]):
            data["sigma_mm"] = sigma[:, 0] * 1e3
        else:
            for k, axis in enumerate("xyz"):
                data[f"sigma_{axis}_mm"] = sigma[:, k] * 1e3
    if measurements.session is not None:
        if measurements.contact:
            kinds = [measurements.contact.get(s, "") for s in measurements.session.tolist()]
            data = {CONTACT_COLUMN: kinds, **data}
        data = {"session": measurements.session, **data}
    text = pd.DataFrame(data).to_csv(index=False, float_format="%.17g", lineterminator="\n")
    write_atomic(path, text)


def _contact_rows(measurements: Measurements) -> np.ndarray | None:
    """(N,) bool: the rows of contact sessions, or None without."""
    if not measurements.contact or measurements.session is None:
        return None
    return np.isin(measurements.session, list(measurements.contact))


def _pick(df: pd.DataFrame, label: str, bases, joint) -> tuple[str, float]:
    """The one column holding `bases[0]` in some unit, and its scale to SI."""
    base = bases[0]
    units = ["", "rad", "deg"] if joint is not None and joint.type == "R" else ["", "m", "mm", "um"]
    found = [
        (f"{base}_{u}" if u else base, u) for u in units if (f"{base}_{u}" if u else base) in df
    ]
    wrong = [
        c
        for c in df.columns
        if re.fullmatch(rf"{re.escape(base)}_(deg|rad|mm|m|um)", c)
        and (c, c.rsplit("_", 1)[1]) not in found
    ]
    if wrong and not found:
        kind = (
            "revolute (use _deg or _rad)"
            if joint and joint.type == "R"
            else "a length (use _mm or _m)"
        )
        raise CalibrationError(f"{label}: column {wrong[0]!r} has the wrong unit: {base} is {kind}")
    if not found:
        options = ", ".join(f"{base}_{u}" if u else base for u in units)
        raise CalibrationError(f"{label}: missing column for {base}; add one of: {options}")
    if len(found) > 1:
        raise CalibrationError(
            f"{label}: columns {found[0][0]!r} and {found[1][0]!r} both give {base}; "
            "keep one so the unit is unambiguous"
        )
    name, u = found[0]
    return name, _SCALE[u]


def _numbers(df: pd.DataFrame, column: str, label: str) -> np.ndarray:
    """A column as float64; a value that is not a finite number is refused with its row."""
    col = df[column]
    if col.dtype.kind in "iuf":  # parsed as numbers (`read_table`): no strings to convert
        values = col.to_numpy(dtype=float)
    else:  # some text ('True' too, which pandas reads as a bool): as before, number by number
        values = pd.to_numeric(col.astype(str).str.strip(), errors="coerce").to_numpy(float)
    bad = ~np.isfinite(values)
    if bad.any():
        row = int(np.flatnonzero(bad)[0])
        # a numeric column holds the parsed value: 1e400 reads as inf, so say what it was
        what = " (infinite, or beyond ±1.8e308)" if np.isinf(values[row]) else ""
        raise CalibrationError(
            f"{label}: row {row + 2}, column {column!r}: {str(col.iloc[row])!r}{what} is "
            "not a finite number; fix or remove that row"
        )
    return values
