"""Argument types of the ``casecal`` command (a leaf of `casecal.cli`): a bad value is
refused while the command line is parsed (one line, exit 2), before any work starts,
instead of failing inside it.

Each is an argparse ``type=`` callable; its `argparse.ArgumentTypeError` message follows
argparse's "argument --flag: " prefix, so it leads with the cause and then says what to
give instead.
"""

from __future__ import annotations

import argparse
import os

from ..errors import CalibrationError
from ..studies.executor import check_scheduler


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


def package(text: str) -> tuple[str, str]:
    """A ROS package's name and folder, NAME=PATH (``--package``)."""
    name, sep, folder = text.partition("=")
    name, folder = name.strip(), folder.strip()
    if not sep or not name or not folder or "/" in name:
        raise argparse.ArgumentTypeError(
            f"{text!r} is not NAME=PATH: give a ROS package's name and its folder, e.g. "
            "--package my_robot_description=~/ws/src/my_robot_description"
        )
    folder = os.path.expanduser(folder)
    if not os.path.isdir(folder):
        raise argparse.ArgumentTypeError(
            f"{text!r}: {folder!r} is not a folder; give the package's folder (the one "
            "holding its package.xml)"
        )
    return name, os.path.abspath(folder)
