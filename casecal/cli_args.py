"""Argument types of the ``casecal`` command: a bad value is refused while the command line
is parsed (one line, exit 2), before any work starts, instead of failing inside it.

Each is an argparse ``type=`` callable; its `argparse.ArgumentTypeError` message follows
argparse's "argument --flag: " prefix, so it leads with the cause and then says what to
give instead.
"""

from __future__ import annotations

import argparse
import os

from .errors import CalibrationError
from .studies.executor import check_scheduler


def workers(text: str) -> int:
    """How many local worker processes: 1 up to four per core (more only slows down)."""
    cores = os.cpu_count() or 1
    digits = text.strip().removeprefix("+")
    value = int(digits) if digits.isascii() and digits.isdigit() else 0
    if value < 1:
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


def size(text: str) -> float:
    """A plausible deviation in the flag's unit: a positive finite number."""
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not (value > 0 and value < float("inf")):
        raise argparse.ArgumentTypeError(
            f"{text!r} is not a size: give a positive number in the flag's unit "
            "(e.g. --plausible-length-mm 10 --plausible-angle-deg 2)"
        )
    return value


def scheduler(text: str) -> str:
    """A dask scheduler address, [tcp://]host:port."""
    try:
        return check_scheduler(text)
    except CalibrationError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


OUTPUTS = {"output": "-o", "deviations_out": "--deviations-out", "camera_out": "--camera-out"}
"""The options that name files a command writes (``report -o`` names a folder)."""


def check_outputs(args: argparse.Namespace) -> None:
    """Refuse, before any work, an output file that is one of the command's input files
    (writing it would replace the user's measurements or targets) or another output's
    file (one would silently replace the other)."""
    outputs = [(flag, getattr(args, dest, None)) for dest, flag in OUTPUTS.items()]
    outputs = [(flag, str(path)) for flag, path in outputs if path and str(path) != "-"]
    seen: dict[str, str] = {}
    for flag, path in outputs:
        key = os.path.realpath(path)
        if key in seen:
            raise CalibrationError(
                f"{seen[key]} and {flag} both name {path!r}: one file would replace the "
                "other; give each its own name"
            )
        seen[key] = flag
        for dest, value in vars(args).items():
            if dest in OUTPUTS or dest == "func" or not isinstance(value, str):
                continue
            if value != "-" and _same_file(path, value):
                raise CalibrationError(
                    f"{flag} {path!r} is also the file read as {dest.replace('_', ' ')}: "
                    "writing it would replace that input; give the output another name"
                )


def _same_file(a: str, b: str) -> bool:
    try:
        return os.path.isfile(b) and os.path.samefile(a, b)
    except OSError:  # `a` does not exist yet: a new file is no input
        return False
