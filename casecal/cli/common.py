"""What the ``casecal`` commands share: robot loading, the shared options, lengths and
angles at the edge, and the quiet/verbose switches.

A leaf of the command-line package: it imports no other module of `casecal.cli` except
`casecal.cli.argtypes`.
"""

from __future__ import annotations

import argparse
import logging
import math
import sys

from ..errors import CalibrationError
from ..model.catalog import load_robot
from ..model.names import namesake_note
from . import argtypes

log = logging.getLogger("casecal.cli")

_LENGTH_UNITS = {"m": 1.0, "mm": 1e-3, "um": 1e-6}


class Output:
    """How much the running command says: `quiet` (-q) drops notes and summaries,
    `verbose` (-v, -vv) adds progress lines and log records (set by `casecal.cli.main`)."""

    quiet = False
    verbose = 0


def say(*values, **kwargs) -> None:
    """`print` to standard output, unless -q: a summary or note, not a requested output."""
    if not Output.quiet:
        _print(*values, **kwargs)


def note(text: str) -> None:
    """A note line on standard error (``casecal: note: ...``), unless -q."""
    if not Output.quiet:
        _print(text, file=sys.stderr)


def _print(*values, file=None, **kwargs) -> None:
    """`print`, with what the stream's encoding cannot show (a file name's undecodable
    bytes) as backslash escapes instead of a UnicodeEncodeError after the work is done."""
    stream = sys.stdout if file is None else file
    try:
        print(*values, file=stream, **kwargs)
    except UnicodeEncodeError:
        encoding = getattr(stream, "encoding", None) or "utf-8"
        text = kwargs.get("sep", " ").join(map(str, values))
        print(text.encode(encoding, "backslashreplace").decode(encoding), file=stream,
              end=kwargs.get("end", "\n"), flush=kwargs.get("flush", False))  # fmt: skip


def add_output_switches(p: argparse.ArgumentParser, default) -> None:
    """-v/--verbose and -q/--quiet on `p` (`default` argparse.SUPPRESS after a command, so
    that the top level's count stands when the command's line has none)."""
    p.add_argument(
        "-v",
        "--verbose",
        action="count",
        default=default,
        help="show the fit's progress, one line per iteration whatever its size, and log "
        "what the library does (kernel compiles); -vv for debug detail",
    )
    p.add_argument(
        "-q",
        "--quiet",
        action="store_true",
        default=False if default is not argparse.SUPPRESS else default,
        help="print only errors, warnings and what was asked for: the files written (a "
        "pipe gets the CSV alone from simulate or compensate -o -) and the tables "
        "of robots, show, observability, validate and compare and of identify --holdout. "
        "Drops the fit summaries and 'written' lines on standard output, the report's "
        "progress, and the notes and fit progress lines on standard error",
    )


def command(sub, name: str, **kwargs) -> argparse.ArgumentParser:
    """A subcommand's parser, with -v and -q after the command name too."""
    switches = argparse.ArgumentParser(add_help=False)
    add_output_switches(switches, argparse.SUPPRESS)
    return sub.add_parser(name, parents=[switches], **kwargs)


def parse_length(text: str) -> float:
    """'0.01mm', '10um', '1e-5m' or a bare number (mm) to metres."""
    t = text.strip().lower().replace("µm", "um")
    for suffix in ("mm", "um", "m"):
        if t.endswith(suffix):
            number, scale = t[: -len(suffix)], _LENGTH_UNITS[suffix]
            break
    else:
        number, scale = t, 1e-3
    try:
        value = float(number) * scale
    except ValueError:
        raise CalibrationError(
            f"{text!r} is not a length; write e.g. 0.01mm, 10um or 1e-5m"
        ) from None
    if not math.isfinite(value) or value < 0:
        raise CalibrationError(f"{text!r} must be a finite, non-negative length")
    return value


def parse_angle(text: str) -> float:
    """'0.01deg', '1e-4rad' or a bare number (degrees) to radians."""
    t = text.strip().lower()
    scale, number = math.pi / 180, t
    if t.endswith("deg"):
        number = t[:-3]
    elif t.endswith("rad"):
        scale, number = 1.0, t[:-3]
    try:
        value = float(number) * scale
    except ValueError:
        raise CalibrationError(f"{text!r} is not an angle; write e.g. 0.01deg or 2e-4rad") from None
    if not math.isfinite(value) or value < 0:
        raise CalibrationError(f"{text!r} must be a finite, non-negative angle")
    return value


def add_robot_options(p: argparse.ArgumentParser) -> None:
    """--base-link, --tip-link and --package: for the commands that read a robot file."""
    group = p.add_argument_group("URDF and xacro robots")
    for end in ("base", "tip"):
        group.add_argument(
            f"--{end}-link",
            metavar="LINK",
            default=argparse.SUPPRESS,
            help=f"the chain's {end} link (default: "
            + (
                "the root)"
                if end == "base"
                else "the end of the one movable chain; several, comma-separated: a "
                "kinematic tree measured at each, CSV columns LINK_x_mm …)"
            ),
        )
    group.add_argument(
        "--package",
        dest="packages",
        action="append",
        type=argtypes.package,
        default=argparse.SUPPRESS,
        metavar="NAME=PATH",
        help="a ROS package's folder, for $(find NAME) and package://NAME/ in a .xacro "
        "file (repeatable; folders above the file are found without it)",
    )


def robot_for(args: argparse.Namespace, name: str):
    """`load_robot(name)`, with --base-link, --tip-link (several, comma-separated: a
    kinematic tree) and --package for a URDF or xacro file."""
    note_text = namesake_note(name)  # a catalog name wins over a file named alike: say so
    if note_text:
        note(f"casecal: note: {note_text}")
    if not str(name).lower().endswith((".urdf", ".xacro")):
        robot = load_robot(name)
        log.info("robot %s from %s: %d joints (%s)", robot.name, name, robot.dof, robot.convention)
        return robot
    ends = {k: getattr(args, k, None) for k in ("base_link", "tip_link")}
    tips = ends["tip_link"]
    if tips is not None and "," in tips:
        ends["tip_link"] = [t.strip() for t in tips.split(",")]
        if not all(ends["tip_link"]):
            raise CalibrationError(
                f"--tip-link {tips!r}: give link names separated by commas, e.g. "
                "--tip-link right_marker,left_marker"
            )
    packages = getattr(args, "packages", None)
    robot = load_robot(name, **ends, packages=dict(packages) if packages else None)
    log.info("robot %s from %s: %d joints (%s)", robot.name, name, robot.dof, robot.convention)
    return robot


PARAMS_HELP = (
    "parameters: names, families or 'all', comma-separated, e.g. "
    "'theta*,a*,d*' or '*.offset' (default: the paper's theta, a, d, a URDF robot's "
    "joint origins, and any error terms; 'a*' never means alpha)"
)

ROBOT_OUT_HELP = (
    "write the calibrated robot here, in the format its extension names: .toml (casecal's "
    "robot file: everything), .urdf (a URDF robot's own file with the calibrated numbers; "
    "a DH robot as a new URDF) or .yaml (UR kinematics file); read back and checked before "
    "it replaces anything, what the format cannot hold said on standard error"
)


def one_line_warning(message, category, filename, lineno, file=None, line=None):
    """`warnings.showwarning` of the command: one line, no source location."""
    print(f"casecal: warning: {message}", file=sys.stderr)


def add_json_option(p) -> None:
    """--json FILE: the command's result also as one JSON object (keys in the README)."""
    p.add_argument(
        "--json",
        metavar="FILE",
        help="also write the result as one JSON object (keys in the README); "
        "'-' for standard output",
    )


def json_text(data: dict) -> str:
    """`data` as indented JSON text (no NaN: `casecal.identification.result_dict`)."""
    import json

    return json.dumps(data, indent=2, allow_nan=False) + "\n"


def write_json(path: str, data: dict) -> None:
    """Write `data` as indented JSON to `path`, atomically."""
    from ..textio import write_atomic

    write_atomic(path, json_text(data))
