"""ABB RAPID joint targets (.mod, .modx, .prg): ``jointtarget`` literals
``[[j1,...,j6],[eax_a,...,eax_f]]``.

A joint target is the literal of a ``jointtarget`` declaration (``CONST``/``PERS``/``VAR``,
arrays of them too), of an assignment to a variable declared ``jointtarget`` in the file,
or the first argument of ``MoveAbsJ``; statements may span lines. The robot axes are in
degrees (mm for a linear axis), written back with 6 decimals (1e-6°; a RobotWare ``num``
holds about 7 significant digits, 1e-5° at 180°, so the controller keeps less than what
is written). External axes (``9E9`` where unused) and every other character are kept as
they are. Left as they are and listed: ``robtarget`` literals (Cartesian) and joint values
computed at run time (``CalcJointT``, ``CJointT``). Refused with the line: a robot axis that
is not a number literal, a literal that is not ``[[six values],[six values]]``, and an
assignment to a part of a jointtarget (``jt.robax.rax_1 := ...``), which would undo its
compensation at run time. A reference (``MoveAbsJ jt1``, ``jt2 := jt1``) is no target.
"""

from __future__ import annotations

import re

import numpy as np

from ..errors import CalibrationError
from ._text import Found, Lines, Target, blank, check_dof, closing, number, split_top

COMMENT = "!"
NAME = "RAPID"
_FLAGS = re.IGNORECASE
_DECL = re.compile(
    r"\b(?:CONST|PERS|VAR)\s+(jointtarget|robtarget)\s+(\w+)\s*(\{[^}]*\})?\s*(:=)?", _FLAGS
)
_ASSIGN = re.compile(r"(?<![\\.\w])(\w+)\s*(\{[^}]*\})?\s*:=", _FLAGS)
_PART = re.compile(r"\.\s*(robax|extax)\b[\w.\s]*:=", _FLAGS)
_MOVE_ABSJ = re.compile(r"\bMoveAbsJ\b", _FLAGS)
_MOVE_CARTESIAN = re.compile(r"\bMove(?!AbsJ\b|ExtJ\b)\w*\b", _FLAGS)


def find(text: str, robot) -> Found:
    """The literal joint targets of a RAPID module and the targets left as they are.

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
    names = {
        m.group(2).lower() for m in _DECL.finditer(masked) if m.group(1).lower() == "jointtarget"
    }
    found = Found([], [])
    start = 0
    for m in re.finditer(";", masked + ";"):
        _statement(text, masked, start, m.start(), names, robot, line_of, found)
        start = m.end()
    found.targets.sort(key=lambda t: t.spans[0][0])
    found.skipped.sort()
    return found


def _statement(text, masked, start, end, names, robot, line_of, found: Found) -> None:
    """Find the targets of the statement masked[start:end] (offsets in the whole text)."""
    s = masked[start:end]
    if (part := _PART.search(s)) is not None:
        raise CalibrationError(
            f"line {line_of(start + part.start())}: assigns part of a jointtarget at run time; "
            "casecal compensates whole literal jointtargets only: write the whole target"
        )
    decl = _DECL.search(s)
    if decl:
        if not decl.group(4):
            return
        value = _value_start(masked, start + decl.end(), end)
        if decl.group(1).lower() == "robtarget":
            if value is not None and masked[value] == "[":
                found.skipped.append((line_of(value), "robtarget (Cartesian): left as is"))
            return
        _literal(text, masked, value, end, robot, line_of, found)
        return
    if (move := _MOVE_ABSJ.search(s)) is not None:
        args = split_top(masked, start + move.end(), end)
        args = [a for a in args if not masked[a[0] : a[1]].lower().startswith("\\conc")]
        if args and masked[args[0][0]] == "[":
            _literal(text, masked, args[0][0], end, robot, line_of, found)
        return
    if (move := _MOVE_CARTESIAN.search(s)) is not None:
        args = split_top(masked, start + move.end(), end)
        if any(masked[a] == "[" for a, _ in args[:2]):
            found.skipped.append((line_of(args[0][0]), "robtarget (Cartesian): left as is"))
        return
    for m in _ASSIGN.finditer(s):
        if m.group(1).lower() in names:
            value = _value_start(masked, start + m.end(), end)
            _literal(text, masked, value, end, robot, line_of, found)


def _value_start(masked: str, at: int, end: int) -> int | None:
    while at < end and masked[at].isspace():
        at += 1
    return at if at < end else None


def _literal(text, masked, at, end, robot, line_of, found: Found) -> None:
    """The jointtarget literal (or array of them) starting at `at`; a reference or a
    function's value (not a literal) is listed or left alone."""
    if at is None:
        return
    if masked[at] != "[":
        word = re.match(r"\w+", masked[at:end])
        if word and masked[at + word.end() : end].lstrip().startswith("("):
            found.skipped.append(
                (line_of(at), f"joint values computed at run time ({word.group()}): left as is")
            )
        elif not (word and not masked[at + word.end() : end].strip()):
            raise CalibrationError(
                f"line {line_of(at)}: a jointtarget given by an expression; casecal "
                "compensates literal jointtargets [[j1,...,j6],[e1,...,e6]] only"
            )
        return
    close = closing(masked, at, "[]")
    if close < 0 or close >= end:
        raise CalibrationError(f"line {line_of(at)}: a jointtarget literal whose '[' is not closed")
    _targets(text, masked, at, close, robot, line_of, found)


def _targets(text, masked, at, close, robot, line_of, found: Found) -> None:
    """The jointtarget (or array of them) masked[at:close + 1]."""
    parts = split_top(masked, at + 1, close)
    is_target = len(parts) == 2 and all(
        masked[a] == "[" and masked.find("[", a + 1, b) < 0 for a, b in parts
    )
    if not is_target:
        if parts and all(masked[a] == "[" for a, _ in parts):
            for a, b in parts:  # an array of jointtargets
                _targets(text, masked, a, b - 1, robot, line_of, found)
            return
        raise CalibrationError(
            f"line {line_of(at)}: a jointtarget literal must be [[j1,...,j6],[e1,...,e6]] "
            "of numbers"
        )
    (a, b), _extax = parts
    axes = split_top(masked, a + 1, b - 1)
    line = line_of(a)
    if len(axes) != 6:
        raise CalibrationError(
            f"line {line}: a jointtarget's robot axes are six values, not {len(axes)}"
        )
    spans, q, units = [], [], []
    for i, joint in enumerate(robot.controller_joints):
        value = number(text, axes[i], line, f"robot axis {i + 1}")
        unit = "deg" if joint.type == "R" else "mm"
        spans.append(axes[i])
        q.append(value * (np.pi / 180 if unit == "deg" else 1e-3))
        units.append(unit)
    found.targets.append(Target(line, tuple(spans), np.array(q), tuple(units)))


def header_at(text: str) -> int:
    """Where the header comment goes: after the ``MODULE`` line, else at the start."""
    m = re.search(r"^[ \t]*MODULE\b.*$", text, re.IGNORECASE | re.MULTILINE)
    if not m:
        return 0
    stop = text.find("\n", m.end())
    return len(text) if stop < 0 else stop + 1
