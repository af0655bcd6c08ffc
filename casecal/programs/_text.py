"""What every program format shares: literal targets found in a text, comments and
strings blanked out, numbers read and written at the files' edges (`casecal.programs`)."""

from __future__ import annotations

import bisect
import re
from dataclasses import dataclass

import numpy as np

from ..errors import CalibrationError

NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")
"""A number literal as KRL, RAPID, URScript and CSV write it (no spaces, no hex)."""

TO_SI = {"deg": np.pi / 180, "rad": 1.0, "mm": 1e-3, "m": 1.0, "um": 1e-6}
DECIMALS = {"deg": 6, "rad": 8, "mm": 6, "m": 9, "um": 3}
"""Decimals written per unit: 1e-6° (1.7e-8 rad), 1e-8 rad, 1e-6 mm (1 nm) for the robot
languages; at a lever of 1 m each joint's rounding moves the tool by at most 9 nm."""


@dataclass(frozen=True)
class Target:
    """One literal joint target in a program's text.

    Attributes
    ----------
    line : int
        1-based line of the target's first value.
    spans : tuple of (int, int)
        Per controller joint, where its number stands in the text (start, end offsets).
    q : ndarray, shape (dof,)
        The values, rad (R) or m (P).
    units : tuple of str
        Per joint, the unit the text writes it in ("deg", "rad", "mm", "m", "um").
    """

    line: int
    spans: tuple[tuple[int, int], ...]
    q: np.ndarray
    units: tuple[str, ...]


@dataclass
class Found:
    """What a format's parser found: the targets, and the lines left as they are."""

    targets: list[Target]
    skipped: list[tuple[int, str]]


class Lines:
    """Line numbers of offsets in a text (1-based)."""

    def __init__(self, text: str):
        self._starts = [m.end() for m in re.finditer("\n", text)]

    def __call__(self, offset: int) -> int:
        return bisect.bisect_right(self._starts, offset) + 1


def blank(text: str, comment: str, quotes: str = '"') -> str:
    """`text` with its comments (from `comment` to the line's end) and string literals
    replaced by spaces: the same length and line breaks, so offsets and lines still hold."""
    out = list(text)
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if c in quotes:
            end = text.find(c, i + 1)
            stop = text.find("\n", i + 1)
            end = end if end >= 0 and (stop < 0 or end < stop) else (stop if stop >= 0 else n)
            for k in range(i, min(end + 1, n)):
                if text[k] not in "\r\n":
                    out[k] = " "
            i = end + 1
        elif c == comment:
            end = text.find("\n", i)
            end = n if end < 0 else end
            for k in range(i, end):
                if text[k] != "\r":
                    out[k] = " "
            i = end
        else:
            i += 1
    return "".join(out)


def closing(masked: str, start: int, pair: str) -> int:
    """Offset of the bracket closing the one at `start` (pair such as "[]"), or -1."""
    depth = 0
    for k in range(start, len(masked)):
        if masked[k] == pair[0]:
            depth += 1
        elif masked[k] == pair[1]:
            depth -= 1
            if depth == 0:
                return k
    return -1


def split_top(masked: str, start: int, end: int) -> list[tuple[int, int]]:
    """The comma-separated parts of masked[start:end] outside brackets, as (start, end)
    offsets with the surrounding white space left out."""
    parts, depth, first = [], 0, start
    for k in range(start, end + 1):
        c = masked[k] if k < end else ","
        if c in "([{":
            depth += 1
        elif c in ")]}":
            depth -= 1
        elif c == "," and depth == 0:
            a, b = first, k
            while a < b and masked[a].isspace():
                a += 1
            while b > a and masked[b - 1].isspace():
                b -= 1
            parts.append((a, b))
            first = k + 1
    return parts


def number(text: str, span: tuple[int, int], line: int, what: str) -> float:
    """The number literal at `span`; a value that is not one is refused with its line."""
    token = text[span[0] : span[1]]
    if not NUMBER.fullmatch(token):
        shown = " ".join(token.split())[:40]
        raise CalibrationError(
            f"line {line}: {what} is {shown!r}, not a number: casecal compensates literal "
            "joint values only; write the number there, or compensate the program that "
            "computes it"
        )
    return float(token)


def fixed(value: float, unit: str) -> str:
    """`value` (SI) written in `unit` with `DECIMALS` decimals, never as ``-0.000000``."""
    x = round(value / TO_SI[unit], DECIMALS[unit]) + 0.0
    return f"{x:.{DECIMALS[unit]}f}"


def check_dof(dof: int, most: int, language: str) -> None:
    if dof > most:
        raise CalibrationError(
            f"the robot has {dof} joints; {language}'s joint targets hold {most} robot axes "
            "(the rest are external axes, which casecal leaves alone): compensate this "
            "robot's joint arrays instead (casecal.compensate)"
        )
