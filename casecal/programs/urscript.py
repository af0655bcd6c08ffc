"""URScript joint targets (.script, .urscript): list literals ``[q1, ..., q6]``.

A joint target is a list literal given as the position of ``movej``, ``movel``,
``movep`` or ``servoj`` (both positions of ``movec``), or assigned (``q1 = [...]``,
``global q1 = [...]``) to a variable the file passes to one of them. Values are radians
(m for a linear axis), written back with 8 decimals (1e-8 rad); ``d2r(90)`` is read as
degrees and written back inside its ``d2r(...)`` with 6 decimals. Left as they are and
listed: pose targets ``p[...]`` (Cartesian) and positions computed at run time
(``get_inverse_kin(...)``, a variable never assigned a literal here). Refused with the
line: a list value that is neither a number nor ``d2r(number)``, and a list whose length
is not the robot's joint count.
"""

from __future__ import annotations

import re

import numpy as np

from ..errors import CalibrationError
from ._text import NUMBER, Found, Lines, Target, blank, closing, number, split_top

COMMENT = "#"
NAME = "URScript"
_MOVE = re.compile(r"(?<![\w.])(movej|movel|movep|servoj|movec)\s*\(")
_ASSIGN = re.compile(
    r"^[ \t]*(?:(?:global|local)[ \t]+)?([A-Za-z_]\w*)[ \t]*=(?!=)[ \t]*", re.MULTILINE
)
_D2R = re.compile(rf"d2r\(\s*({NUMBER.pattern})\s*\)")
_D2R_LIST = re.compile(r"d2r\(\s*\[")
_KEYWORD = re.compile(r"([A-Za-z_]\w*)\s*=(?!=)\s*")
_POSITIONS = {
    "movej": ("q",),
    "servoj": ("q",),
    "movel": ("pose",),
    "movep": ("pose",),
    "movec": ("pose_via", "pose_to"),
}
"""Each move's position parameters, by the names its keyword arguments give them."""


def find(text: str, robot) -> Found:
    """The literal joint targets of a URScript program and the targets left as they are.

    Parameters
    ----------
    text : str
    robot : Robot

    Returns
    -------
    Found
    """
    masked = blank(text, COMMENT, quotes="\"'")
    line_of = Lines(text)
    found = Found([], [])
    names: dict[str, int] = {}  # variables given as positions: the line of the first move
    for m in _MOVE.finditer(masked):
        close = closing(masked, m.end() - 1, "()")
        if close < 0:
            raise CalibrationError(f"line {line_of(m.start())}: {m.group(1)}( is not closed")
        positions = []  # positional first, then given by keyword (movej(q=[...]))
        for a, b in split_top(masked, m.end(), close):
            key = _KEYWORD.match(masked, a, b)
            if key is None:
                positions.append((a, b))
            elif key.group(1) in _POSITIONS[m.group(1)]:
                positions.append((key.end(), b))
        for a, b in positions[: len(_POSITIONS[m.group(1)])]:
            _position(text, masked, a, b, robot, line_of, found, names)
    assigned = set()
    for m in _ASSIGN.finditer(masked):
        name, at = m.group(1), m.end()
        if name not in names:
            continue
        assigned.add(name)
        stop = masked.find("\n", at)
        end = len(masked) if stop < 0 else stop
        if masked.startswith("[", at):
            close = closing(masked, at, "[]")
            _position(
                text, masked, at, close + 1 if close >= 0 else end, robot, line_of, found, None
            )
        elif masked.startswith("p[", at):
            found.skipped.append((line_of(at), f"pose {name} (Cartesian): left as is"))
        else:
            found.skipped.append((line_of(at), f"{name}: computed at run time, left as is"))
    for name in names.keys() - assigned:
        found.skipped.append((names[name], f"{name}: not assigned a list here, left as is"))
    found.targets.sort(key=lambda t: t.spans[0][0])
    found.skipped.sort()
    return found


def _position(text, masked, a, b, robot, line_of, found: Found, names) -> None:
    """The position argument masked[a:b]: a list literal joins `found`; a variable is
    noted in `names` (None: it must be a literal)."""
    line = line_of(a)
    arg = masked[a:b]
    if arg.startswith("["):
        if not arg.endswith("]") or closing(masked, a, "[]") != b - 1:
            raise CalibrationError(f"line {line}: a joint list whose '[' is not closed")
        _list(text, masked, a, b, robot, line, found)
    elif arg.startswith("p["):
        found.skipped.append((line, "pose target p[...] (Cartesian): left as is"))
    elif _D2R_LIST.match(arg):  # d2r([...]): the whole list in degrees
        start = a + arg.index("[")
        close = closing(masked, start, "[]")
        if close < 0 or masked[close + 1 : b].strip() != ")":
            raise CalibrationError(f"line {line}: d2r([...]) is not a closed joint list")
        _list(text, masked, start, close + 1, robot, line, found, degrees=True)
    elif names is not None and re.fullmatch(r"[A-Za-z_]\w*", arg):
        names.setdefault(arg, line)
    else:
        word = re.match(r"[A-Za-z_]\w*", arg)
        what = f"{word.group()}(...)" if word else "an expression"
        found.skipped.append((line, f"position computed at run time ({what}): left as is"))


def _list(text, masked, a, b, robot, line, found: Found, degrees: bool = False) -> None:
    """The joint list masked[a:b] (``[...]``) as a target; `degrees`: inside d2r(...)."""
    items = split_top(masked, a + 1, b - 1)
    if len(items) != robot.dof:
        raise CalibrationError(
            f"line {line}: a joint list of {len(items)} values for a robot with {robot.dof} joints"
        )
    spans, q, units = [], [], []
    for i, ((s, e), joint) in enumerate(zip(items, robot.controller_joints, strict=True), start=1):
        d2r = None if degrees else _D2R.fullmatch(masked[s:e])
        if d2r:
            s, e = s + d2r.start(1), s + d2r.end(1)
            unit = "deg"
        elif degrees:
            unit = "deg"
        else:
            unit = "rad" if joint.type == "R" else "m"
        value = number(text, (s, e), line, f"joint {i}")
        spans.append((s, e))
        q.append(np.deg2rad(value) if unit == "deg" else value)
        units.append(unit)
    found.targets.append(Target(line, tuple(spans), np.array(q), tuple(units)))


def header_at(text: str) -> int:
    """Where the header comment goes: the start of the file."""
    return 0
