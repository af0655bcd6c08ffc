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
_PART = re.compile(r"\.\s*(robax|extax)\b(\s*\.\s*\w+)?\s*:=", _FLAGS)
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
    if (part := _PART.search(masked)) is not None:
        raise CalibrationError(
            f"line {line_of(part.start())}: assigns part of a jointtarget at run time; "
            "casecal compensates whole literal jointtargets only: write the whole target"
        )
    found = Found([], [])
    seen: set[int] = set()  # values found twice (a declaration is an assignment too)
    for at, end, kind in _values(masked, names):
        if at is None or at in seen:
            continue
        seen.add(at)
        if kind == "jointtarget":
            _literal(text, masked, at, end, robot, line_of, found)
        elif masked[at] == "[":
            found.skipped.append((line_of(at), "robtarget (Cartesian): left as is"))
    found.targets.sort(key=lambda t: t.spans[0][0])
    found.skipped.sort()
    return found


def _values(masked: str, names: set[str]):
    """(start, end of its statement, kind) of every value that may be a target: the
    initial values of declarations, assignments to the file's jointtarget variables and
    MoveAbsJ's position ("jointtarget"), literal positions of the other Move instructions
    ("robtarget"). A statement ends at its ';' and may span lines."""

    def end_of(at: int) -> int:
        stop = masked.find(";", at)
        return len(masked) if stop < 0 else stop

    for m in _DECL.finditer(masked):
        if m.group(4):
            end = end_of(m.end())
            yield _value_start(masked, m.end(), end), end, m.group(1).lower()
    for m in _ASSIGN.finditer(masked):
        if m.group(1).lower() in names:
            end = end_of(m.end())
            yield _value_start(masked, m.end(), end), end, "jointtarget"
    for m in _MOVE_ABSJ.finditer(masked):
        end = end_of(m.end())
        args = split_top(masked, m.end(), end)
        args = [a for a in args if not masked[a[0] : a[1]].lower().startswith("\\conc")]
        if args:
            yield args[0][0], end, "jointtarget"
    for m in _MOVE_CARTESIAN.finditer(masked):
        end = end_of(m.end())
        literal = [a for a, _ in split_top(masked, m.end(), end)[:2] if masked[a] == "["]
        if literal:
            yield literal[0], end, "robtarget"


def _value_start(masked: str, at: int, end: int) -> int | None:
    while at < end and masked[at].isspace():
        at += 1
    return at if at < end else None


def _literal(text, masked, at, end, robot, line_of, found: Found) -> None:
    """The jointtarget literal (or array of them) starting at `at`; a reference (with its
    optional switches, ``jt1\\NoEOffs``) is no target, a function's value is listed."""
    if masked[at] != "[":
        word = re.match(r"\w+", masked[at:end])
        rest = masked[at + (word.end() if word else 0) : end].split(",")[0].split("\\")[0]
        if word and rest.lstrip().startswith("("):
            found.skipped.append(
                (line_of(at), f"joint values computed at run time ({word.group()}): left as is")
            )
        elif not (word and not rest.strip()):
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
