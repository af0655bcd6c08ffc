"""Writing what a fit found: the checks before (the -o format, the fit passed), the robot
file and the deviations (`casecal.model.save.export`, verified), the progress of a fit.

Shared by ``identify``, ``calibrate-until`` and ``convert``; imports no command module.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

from ..data.files import write_atomic, write_together
from ..errors import CalibrationError
from ..model.names import is_path, path_text
from ..model.parameters import unit
from .common import Output, note, say

PROGRESS_POSES = 10_000
"""Fits of at least this many poses show their iterations on stderr as they go (any fit
with -v; none with -q)."""


class Progress:
    """A fit's progress callback: one stderr line per iteration, rewritten in place on a
    terminal (a log file gets one line each)."""

    def __init__(self, n_poses: int) -> None:
        self.n_poses = n_poses
        self.start = time.perf_counter()
        self.rewrite = sys.stderr.isatty()

    def __call__(self, line: str) -> None:
        elapsed = time.perf_counter() - self.start
        text = f"casecal: {self.n_poses} poses, {line} ({elapsed:.1f} s)"
        if self.rewrite:
            print(f"\r{text}", end="", file=sys.stderr)
        else:
            print(text, file=sys.stderr)

    def end(self) -> None:
        """End the rewritten line (a terminal's)."""
        if self.rewrite:
            print(file=sys.stderr)


def progress_line(n_poses: int) -> Progress | None:
    """The progress callback of a fit of `n_poses`: long fits, or any with -v; none with -q."""
    if Output.quiet or (n_poses < PROGRESS_POSES and not Output.verbose):
        return None
    return Progress(n_poses)


def add_sizes(p: argparse.ArgumentParser) -> None:
    """--plausible-length-mm and --plausible-angle-deg."""
    from .argtypes import size

    for flag, what, ratio, default in (
        ("--plausible-length-mm", "lengths, mm", "0.4", "2.5"),
        ("--plausible-angle-deg", "angles, degrees", "0.2", "0.5"),
    ):
        p.add_argument(
            flag,
            type=size,
            default=None,
            metavar="SIZE",
            help=f"the largest deviation expected of the robot's {what}: a parameter "
            "whose standard error exceeds it (while it moves the points by less than the "
            f"noise) is held, and an estimate whose standard error exceeds {ratio} of it "
            "is poorly determined (not written) (default: the robot file's [plausible], "
            f"else {default})",
        )


def with_sizes(robot, args: argparse.Namespace):
    """`robot` with --plausible-length-mm and --plausible-angle-deg, over its file's."""
    length, angle = args.plausible_length_mm, args.plausible_angle_deg
    if length is None and angle is None:
        return robot
    return robot.with_plausible(
        length=None if length is None else length * 1e-3,
        angle=None if angle is None else math.radians(angle),
    )


def check_fit(cal, strict: bool, what: str) -> None:
    """Refuse to write a fit that failed, or (--strict) one that left parameters blind."""
    if strict and cal.unidentifiable:
        raise CalibrationError(
            f"--strict: the data cannot identify {', '.join(cal.unidentifiable)}; ask for "
            f"fewer parameters or measure more varied {what} (nothing written)"
        )
    if not cal.success:
        raise CalibrationError(f"the fit did not pass ({cal.message}); nothing written")


def without_poorly_determined(cal, meas, options, strict):
    """The calibration to write: poorly determined estimates held at nominal, the rest
    refitted (`casecal.identification.usable`); a refit that fails writes nothing."""
    from ..identification.calibration import display_unit
    from ..identification.usable import held_as_poorly_determined, hold_poorly_determined

    poorly = held_as_poorly_determined(cal)
    if not poorly:
        return cal
    shown = []
    for name in poorly:
        unit, factor = display_unit(name)
        shown.append(f"{name} ± {cal.standard_errors[name] * factor:.3g} {unit}")
    say(
        f"\n{', '.join(shown)}: poorly determined, so not written: held at nominal and the "
        "other parameters refitted without them. The calibration written:\n"
    )
    refit = hold_poorly_determined(cal, meas, **options)
    say(refit.summary())
    held = [n for n in cal.parameters if n not in refit.parameters]
    if not refit.success:
        raise CalibrationError(
            f"with {', '.join(held)} held at nominal the fit does not pass "
            f"({refit.message}); nothing written: measure more, better-spread poses, or "
            "leave these parameters out of --parameters"
        )
    if strict and refit.unidentifiable:
        raise CalibrationError(
            f"--strict: the data cannot identify {', '.join(refit.unidentifiable)}; ask for "
            "fewer parameters or measure more varied poses (nothing written)"
        )
    return refit


def how_to_load(path, robot) -> str:
    """How to load the written robot file `path` again."""
    if robot.is_tree and str(path).lower().endswith(".urdf"):  # the file has every link
        return f"load it with casecal.load_robot or --tip-link {','.join(robot.tips)}"
    return "load it with casecal.load_robot"


def write_calibrated(args: argparse.Namespace, robot) -> None:
    """Write -o's calibrated robot file, recording which nominal it came from."""
    if args.output:
        write_atomic(args.output, robot_file_text(args, robot))
        say(f"\ncalibrated robot written to {args.output} ({how_to_load(args.output, robot)})")


def check_robot_format(args: argparse.Namespace, robot) -> None:
    """Refuse, before the fit, an -o format that cannot hold this robot (a UR kinematics
    file for a robot without UR joints): the calibrated one would not fit either."""
    if args.output:
        from ..model.save import robot_text

        robot_text(robot, args.output)


def nominal_seen_from(origin: str, output) -> str:
    """The ``calibrated_from`` of a robot file written to `output` whose nominal robot is
    `origin` (a catalog name, or a path from the current folder): a path is made relative
    to `output`'s folder, as loading reads it (``./arm``, never ``arm``, a catalog name).

    A file name that is not UTF-8 (bytes the file system holds as they are) cannot go into
    a UTF-8 file: its undecodable bytes become U+FFFD, and the link says it is lost.
    """
    if origin and origin != "-" and is_path(origin):  # a missing file too: kept pointing at it
        origin = path_text(os.path.relpath(Path(origin).resolve(), Path(output).resolve().parent))
    return os.fsencode(origin).decode("utf-8", "replace")


def robot_file_text(args: argparse.Namespace, robot) -> str:
    """The -o file's text in the format its extension names (.toml, .urdf); what that
    format cannot hold is said on standard error."""
    from ..model.save import export

    origin = nominal_seen_from(args.robot, args.output)
    out = export(dataclasses.replace(robot, calibrated_from=origin, auto_beta=False), args.output)
    say_notes(args.output, out)
    return out.text


def say_notes(path, out) -> None:
    """What the checked file `out` (`casecal.model.save.export`) cannot hold: its loss as a
    warning, the rest as notes (dropped by -q), on standard error."""
    for text in out.notes:  # the file read back and checked: what it loses is a warning
        if text == out.statement:
            print(f"casecal: warning: {path}: {text}", file=sys.stderr)
        else:
            note(f"note: {path}: {text}")


def write_outputs(args: argparse.Namespace, cal, files=()) -> None:
    """-o and --deviations-out (and `files`, (path, text) pairs) together: all written to
    temporary files first, then renamed, the robot file last (it is the calibration; the
    others describe it)."""
    files = list(files)
    if args.deviations_out:
        files.append((args.deviations_out, deviations_text(cal, args.deviations_out)))
    if args.output:
        files.append((args.output, robot_file_text(args, cal.robot)))
    write_together(files)  # each file recorded as its rename is done, for Ctrl-C's line
    if args.output:
        say(f"\ncalibrated robot written to {args.output} ({how_to_load(args.output, cal.robot)})")
    if args.deviations_out:
        say(f"deviations with standard errors written to {args.deviations_out}")


def deviations_text(cal, path: str) -> str:
    """--deviations-out's text: JSON (``.json``) or else CSV, SI units beside the table's."""
    if path.endswith(".json"):
        import json

        def number(v: float) -> float | None:  # JSON has no NaN: a held parameter's is null
            return v if np.isfinite(v) else None

        data = {
            n: {
                "deviation": number(cal.deviations[n]),
                "standard_error": number(cal.standard_errors[n]),
                "unit": unit(n),
                "estimated": n in cal.estimated,
            }
            for n in cal.parameters
        }
        return json.dumps(
            {"robot": cal.nominal.name, "method": cal.method, "rms_m": cal.rms, "parameters": data},
            indent=2,
            allow_nan=False,
        )
    table = cal.table.copy()
    table.insert(3, "deviation_si", [cal.deviations[n] for n in cal.parameters])
    table.insert(4, "std_error_si", [cal.standard_errors[n] for n in cal.parameters])
    table.insert(5, "si_unit", [unit(n) for n in cal.parameters])
    return table.to_csv(index=False, float_format="%.12g", lineterminator="\n")
