"""Argument types of the ``casecal`` command: a bad value is refused while the command line
is parsed (one line, exit 2), before any work starts, instead of failing inside it.

Each factory returns an argparse ``type=`` callable; its `argparse.ArgumentTypeError`
message follows argparse's "argument --flag: " prefix, so it leads with the cause and then
says what to give instead.
"""

from __future__ import annotations

import argparse
import math
import os

from .errors import CalibrationError
from .studies.executor import check_scheduler


def _whole(text: str) -> int:
    """`text` as a whole number, or an ArgumentTypeError saying it is not one."""
    try:
        return int(text.strip().replace("_", ""))
    except (ValueError, AttributeError):
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None


def count(least: int = 1, most: int | None = None, hint: str = ""):
    """A whole number from `least` to `most`; `hint` says what to do otherwise."""

    def parse(text: str) -> int:
        value = _whole(text)
        if value < least or (most is not None and value > most):
            bounds = f"at least {least}" if most is None else f"from {least} to {most:,}"
            raise argparse.ArgumentTypeError(
                f"{text!r} is out of range: give a whole number {bounds}{hint}"
            )
        return value

    return parse


def seed(text: str) -> int:
    """A random seed: a whole number, 0 or more (numpy refuses negative seeds)."""
    value = _whole(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"{text!r} is negative: give a seed of 0 or more")
    return value


def positive_number(text: str) -> float:
    """A finite number above zero."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"{text!r}: give a finite number above 0")
    return value


def fraction(text: str) -> float:
    """A number strictly between 0 and 1 (a share of the poses)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not 0 < value < 1:  # also refuses NaN
        raise argparse.ArgumentTypeError(f"{text!r}: give a fraction between 0 and 1, e.g. 0.2")
    return value


def workers(text: str) -> int:
    """How many local worker processes: 1 up to four per core (more only slows down)."""
    cores = os.cpu_count() or 1
    value = _whole(text) if text.strip().lstrip("+-").isdigit() else None
    if value is None or value < 1:
        raise argparse.ArgumentTypeError(
            f"{text!r} is not a number of processes: give a positive number, or leave "
            "--workers out for one per core"
        )
    if value > 4 * cores:
        raise argparse.ArgumentTypeError(
            f"{text!r} is more than four processes per core (this machine has {cores}): "
            f"they would only wait for each other; give at most {4 * cores}, or leave "
            "--workers out for one per core"
        )
    return value


def scheduler(text: str) -> str:
    """A dask scheduler address, [tcp://]host:port."""
    try:
        return check_scheduler(text)
    except CalibrationError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
