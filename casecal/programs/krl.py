"""KUKA KRL joint targets (.src and .dat): aggregates ``{A1 0.0,A2 -90.0,...,E1 0.0}``.

A joint target is a brace aggregate with components ``A1`` ... ``A6`` (an ``E6AXIS`` or
``AXIS``, declared, assigned or inline after ``PTP``): robot axes in degrees (mm for a
linear axis), written back with 6 decimals (1e-6°). External axes ``E1`` ... ``E6`` and
every other character are kept as they are. Left as they are and listed: Cartesian targets
(``E6POS``/``POS`` aggregates with ``X``, ``Y``, ``Z``), relative moves (``PTP_REL``), and
aggregates that give only some of the robot's axes (the rest come from where the robot
stands). Refused with the line: an axis value that is not a number literal (a variable, an
expression) and an aggregate left open on its line (KRL statements are one line).
A reference (``PTP XP1``, ``XP2 = XP1``) is no target: the aggregate it names is.
"""

from __future__ import annotations

import re

import numpy as np

from ..errors import CalibrationError
from ._text import Found, Lines, Target, blank, check_dof, closing, number, split_top

COMMENT = ";"
NAME = "KRL"
_AXIS = re.compile(r"A([1-6])", re.IGNORECASE)
_COMPONENT = re.compile(r"([A-Za-z_$][\w$]*)\s+(\S.*)?", re.DOTALL)
_RELATIVE = re.compile(r"\b(S?PTP_REL|S?LIN_REL)\b", re.IGNORECASE)
_CARTESIAN_DECL = re.compile(r"\b(E6POS|POS)\b", re.IGNORECASE)
_MOTION = re.compile(r"\b(S?PTP|S?LIN|S?CIRC)\b", re.IGNORECASE)
_LOOKS = re.compile(r"\bA[1-6]\s+\S|\b(E6AXIS|AXIS)\b", re.IGNORECASE)


def find(text: str, robot) -> Found:
    """The literal joint targets of a KRL file and the targets left as they are.

    Parameters
    ----------
    text : str
    robot : Robot
        Its controller joints say which values are degrees (R) and which mm (P).

    Returns
    -------
    Found
    """
    check_dof(robot.dof, 6, NAME)
    masked = blank(text, COMMENT)
    line_of = Lines(text)
    found = Found([], [])
    k = 0
    while (k := masked.find("{", k)) >= 0:
        line = line_of(k)
        end = closing(masked, k, "{}")
        stop = masked.find("\n", k)
        if end < 0 or (0 <= stop < end):
            start = masked.rfind("\n", 0, k) + 1
            if _LOOKS.search(masked[start : stop if stop >= 0 else len(masked)]):
                raise CalibrationError(
                    f"line {line}: a joint target's '{{' is not closed on its line; KRL "
                    "writes an aggregate on one line"
                )
            k += 1
            continue
        _aggregate(text, masked, k, end, robot, line, found)
        k = end + 1
    return found


def _aggregate(text, masked, start, end, robot, line, found: Found) -> None:
    """Classify the aggregate masked[start:end + 1]; a joint target joins `found`."""
    inner = start + 1
    prefix = re.match(r"\s*([A-Za-z_]\w*)\s*:", masked[inner:end])
    if prefix:
        inner += prefix.end()
    parts = {}
    for a, b in split_top(masked, inner, end):
        m = _COMPONENT.fullmatch(masked[a:b])
        if m:
            parts[m.group(1).upper()] = (a + m.start(2), b) if m.group(2) else (b, b)
    axes = {int(n[1]): span for n, span in parts.items() if _AXIS.fullmatch(n)}
    before = masked[masked.rfind("\n", 0, start) + 1 : start]
    if not axes:
        if {"X", "Y", "Z"} <= set(parts) and (
            _CARTESIAN_DECL.search(before) or _MOTION.search(before)
        ):
            found.skipped.append((line, "Cartesian target (X, Y, Z, A, B, C): left as is"))
        return
    if _RELATIVE.search(before):
        found.skipped.append((line, "relative move: its axis values are increments, left as is"))
        return
    missing = [i for i in range(1, robot.dof + 1) if i not in axes]
    if missing:
        found.skipped.append(
            (
                line,
                f"gives no A{missing[0]}: the missing axes come from where the robot "
                "stands; left as is",
            )
        )
        return
    spans, q, units = [], [], []
    for i, joint in enumerate(robot.controller_joints, start=1):
        span = axes[i]
        value = number(text, span, line, f"A{i}")
        unit = "deg" if joint.type == "R" else "mm"
        spans.append(span)
        q.append(value * (np.pi / 180 if unit == "deg" else 1e-3))
        units.append(unit)
    found.targets.append(Target(line, tuple(spans), np.array(q), tuple(units)))


def header_at(text: str) -> int:
    """Where the header comment goes: after the ``DEF``/``DEFDAT`` line (the ``&`` lines
    above it must stay first), else after the leading ``&`` lines."""
    m = re.search(r"^[ \t]*(GLOBAL\s+)?DEF(DAT|FCT)?\b.*$", text, re.IGNORECASE | re.MULTILINE)
    if m:
        return _after_line(text, m.end())
    offset = 0
    for m in re.finditer(r"^&.*(\n|$)", text, re.MULTILINE):
        if m.start() != offset:
            break
        offset = m.end()
    return offset


def _after_line(text: str, end: int) -> int:
    stop = text.find("\n", end)
    return len(text) if stop < 0 else stop + 1
