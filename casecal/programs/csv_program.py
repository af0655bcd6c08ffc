"""A CSV of joint targets: the columns casecal's readers take (``q1_deg``, ``q1`` or
``q1_rad``, ``q1_mm`` ...; `casecal.data.files.read_joints`), one target per row.

Values are written back in their column's unit as the shortest decimal that reads back as
the same double (Python's ``repr``): CSV is read by programs, so nothing is rounded. Other
columns and every other character are kept as they are. No header comment is written:
casecal's CSV reader refuses ``#`` lines (CSV has no comments), so `ProgramResult.header`
carries it for the caller to keep beside the file. Refused with the line: a joint cell that
is not a number, a row with fewer cells than the header. Commas separate the cells, or tabs
or semicolons when the header has no comma (as `casecal.data.table.read_table`).
"""

from __future__ import annotations

import re
import warnings

import numpy as np

from ..errors import CalibrationError, CalibrationWarning
from ._text import TO_SI, Found, Target, number

COMMENT = None
NAME = "CSV"
_JOINT = re.compile(r"q(\d+)(?:_(deg|rad|mm|m|um))?")


def find(text: str, robot) -> Found:
    """The joint targets of a CSV file, one per row.

    Parameters
    ----------
    text : str
    robot : Robot
        Its controller joints name the columns (`casecal.data.files.read_joints`).

    Returns
    -------
    Found
    """
    rows = list(_rows(text))
    if not rows:
        raise CalibrationError("the CSV file is empty; give a header row and one row per target")
    head_line, start, end = rows[0]
    first = text[start:end]
    sep = next((d for d in ("\t", ";") if d in first and "," not in first), ",")
    header = [text[a:b].strip().strip('"') for a, b in _cells(text, start, end, sep)]
    header[0] = header[0].lstrip("\ufeff").strip().strip('"')  # a byte-order mark kept
    joint_like = [k for k, c in enumerate(header) if _JOINT.fullmatch(c)]
    spans, values = [], []
    for line, start, end in rows[1:]:
        cells = _cells(text, start, end, sep)
        if len(cells) < len(header):
            raise CalibrationError(
                f"line {line}: {len(cells)} cells under a header of {len(header)} "
                f"(line {head_line})"
            )
        spans.append([_unquoted(text, cells[k]) for k in joint_like])
        values.append(
            [
                number(text, s, line, f"column {header[k]!r}")
                for s, k in zip(spans[-1], joint_like, strict=True)
            ]
        )
    q, order, units = _joints(header, joint_like, values, robot)
    found = Found([], [])
    for n, (line, _, _) in enumerate(rows[1:]):
        target_spans = tuple(spans[n][k] for k in order)
        found.targets.append(Target(line, target_spans, q[n], units))
    return found


def _rows(text: str):
    """(line, start, end) of every line; blank lines only at the end (as casecal's CSV
    reader, whose messages number the rows by their line)."""
    offset, blank = 0, None
    for line, raw in enumerate(text.splitlines(keepends=True), start=1):
        body = raw.rstrip("\r\n")
        if not body.strip():
            blank = blank or line
        elif blank:
            raise CalibrationError(
                f"line {blank}: a blank line between rows; delete it (casecal's CSV reader "
                "refuses it)"
            )
        else:
            yield line, offset, offset + len(body)
        offset += len(raw)


def _cells(text: str, start: int, end: int, sep: str) -> list[tuple[int, int]]:
    """(start, end) of each cell of text[start:end], quotes respected."""
    cells, first, quoted = [], start, False
    for k in range(start, end):
        if text[k] == '"':
            quoted = not quoted
        elif text[k] == sep and not quoted:
            cells.append((first, k))
            first = k + 1
    cells.append((first, end))
    return cells


def _unquoted(text: str, span: tuple[int, int]) -> tuple[int, int]:
    a, b = span
    while a < b and text[a].isspace():
        a += 1
    while b > a and text[b - 1].isspace():
        b -= 1
    if b - a >= 2 and text[a] == text[b - 1] == '"':
        a, b = a + 1, b - 1
    return a, b


def _joints(header, joint_like, values, robot):
    """The rows' joint values in SI, read by `casecal.data.files.read_joints` (its column
    rules, unit checks and messages), which of the `joint_like` columns holds each joint,
    and their units."""
    import pandas as pd

    from ..data.files import read_joints

    names = [header[k] for k in joint_like]
    table = np.array(values, dtype=float).reshape(len(values), len(names))
    frame = pd.DataFrame({name: table[:, j] for j, name in enumerate(names)})
    with warnings.catch_warnings():  # a target outside the limits is listed as skipped
        warnings.simplefilter("ignore", CalibrationWarning)
        q = read_joints(frame, robot, "CSV program") if values else np.empty((0, robot.dof))
    order, units = [], []
    for i, joint in enumerate(robot.controller_joints, start=1):
        for j, name in enumerate(names):
            m = _JOINT.fullmatch(name)
            if int(m.group(1)) == i:
                order.append(j)
                units.append(m.group(2) or ("rad" if joint.type == "R" else "m"))
    return q, order, tuple(units)


def render(value: float, unit: str) -> str:
    """`value` (SI) in `unit`, the shortest decimal that reads back as the same double."""
    return repr(float(value / TO_SI[unit]) + 0.0)


def header_at(text: str) -> int:
    """No header comment in a CSV file (see the module's notes)."""
    return 0
