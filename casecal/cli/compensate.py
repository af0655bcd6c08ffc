"""``casecal compensate``: corrected joint targets from a calibrated robot file."""

from __future__ import annotations

import argparse
import io

import numpy as np

from ..errors import CalibrationError
from .common import add_json_option, add_robot_options, command, robot_for, say, write_json


def add_parser(sub) -> None:
    """Register ``compensate`` on the subcommand action `sub`."""
    p = command(
        sub,
        "compensate",
        help="correct joint targets so the real robot reaches where the nominal one would",
        description="Read joint targets (columns q1_deg ... or q1 ...) that a controller "
        "sends to the nominal robot, and write the joint values that bring the calibrated "
        "robot's tool to the nominal robot's pose at those targets (its position for arms "
        "of fewer than six joints). One row out per row in, in degrees (mm for prismatic "
        "joints), with ok = 0 and a reason where a target cannot be corrected (at or near "
        "a singularity, where the correction would be far larger than the calibration "
        "errors justify; not reached; outside the joint limits): those rows keep the "
        "target. A kinematic tree (--tip-link A,B) brings every tip to the nominal "
        "tree's pose of it at once.",
    )
    p.add_argument("robot", metavar="CALIBRATED", help="calibrated robot file (.toml or .urdf)")
    p.add_argument(
        "targets", metavar="CSV", nargs="?", help="joint targets ('-' for standard input)"
    )
    p.add_argument(
        "--program",
        metavar="FILE",
        help="a robot program instead of CSV: KUKA KRL (.src, .dat), ABB RAPID (.mod, .modx, "
        ".prg), URScript (.script, .urscript) or a joint CSV (.csv). Its literal joint targets "
        "are compensated in place; every other character is kept, and a header comment names "
        "the calibration file and its hash. Targets that cannot be corrected, and Cartesian or "
        "computed ones, are left as they were and listed",
    )
    p.add_argument(
        "--format",
        choices=("krl", "rapid", "urscript", "csv"),
        help="the --program's format when its extension does not tell",
    )
    p.add_argument("-o", "--output", required=True, metavar="FILE", help="file to write")
    p.add_argument(
        "--nominal",
        metavar="ROBOT",
        help="the robot the controller believes (default: calibrated_from in the file)",
    )
    p.add_argument(
        "--frame",
        choices=("robot", "instrument"),
        default="robot",
        help="where the targets' poses live. 'robot' (default): the robot's base frame as "
        "the controller defines it, the nominal robot placed where it best fits the "
        "calibrated one; errors that look like a moved base (joint 1's zero, its height) "
        "are left to the base frame, however the calibration split them. 'instrument': "
        "the frame the calibration was measured in, with the nominal robot's base frame "
        "giving where the base stands in it (measured, or a simulation); every error is "
        "corrected, base-like ones too",
    )
    p.add_argument(
        "--position-only",
        action="store_true",
        help="match the tool's position only, with the least joint motion (default for "
        "arms of six or more joints: the whole pose). For a calibration from positions "
        "alone, whose tool orientation may be blind",
    )
    add_json_option(p)
    add_robot_options(p)
    p.set_defaults(func=run)


COMPENSATED_COLUMNS = ("ok", "position_error_mm", "orientation_error_mrad")
"""The columns `run` writes beside the corrected joints: a targets file with them is
compensated already."""


def run(args: argparse.Namespace) -> None:
    """``casecal compensate``: write the corrected targets, one row per target."""
    from ..data.files import read_joints, read_table
    from ..model.compensate import compensate
    from ..textio import write_atomic

    if (args.targets is None) == (args.program is None):
        raise CalibrationError("give the joint targets: a CSV, or --program FILE (one of them)")
    calibrated = robot_for(args, args.robot)
    nominal = robot_for(args, args.nominal) if args.nominal else None
    if args.program is not None:
        return run_program(args, calibrated, nominal)
    if args.format is not None:
        raise CalibrationError("--format goes with --program")
    df, label = read_table(args.targets, "targets file")
    if set(COMPENSATED_COLUMNS) <= set(df.columns):
        raise CalibrationError(
            f"{label} is compensate's output (columns {', '.join(COMPENSATED_COLUMNS)}): its "
            "joints are compensated already, and compensating them again applies the "
            "calibration twice; give the original targets"
        )
    q = read_joints(df, calibrated, label)
    orientation = False if args.position_only else None
    result = compensate(calibrated, q, nominal, frame=args.frame, orientation=orientation)
    columns = {}
    for i, joint in enumerate(calibrated.controller_joints, start=1):
        scale, unit = (180 / np.pi, "deg") if joint.type == "R" else (1e3, "mm")
        columns[f"q{i}_{unit}"] = result.q[:, i - 1] * scale
    columns["ok"] = result.ok.astype(int)
    columns["position_error_mm"] = result.position_error * 1e3
    columns["orientation_error_mrad"] = result.orientation_error * 1e3
    columns["reason"] = list(result.reason)
    import pandas as pd

    buffer = io.StringIO()
    pd.DataFrame(columns).to_csv(buffer, index=False, float_format="%.17g")
    write_atomic(args.output, buffer.getvalue())
    if args.json:
        left = [{"row": int(i), "reason": result.reason[i]} for i in np.flatnonzero(~result.ok)]
        write_json(args.json, _summary(args, len(q), left))
    bad = int((~result.ok).sum())
    say(
        f"wrote {len(q)} corrected targets to {args.output}"
        + (
            f"; {bad} could not be corrected (ok = 0, reason given; they keep the target)"
            if bad
            else ""
        )
    )


def run_program(args: argparse.Namespace, calibrated, nominal) -> None:
    """``casecal compensate --program``: the program with compensated targets, in its own
    encoding (UTF-8, else Windows-1252 as KRL files often are), byte for byte elsewhere."""
    import os

    from ..programs import calibration_header, compensate_program, program_format
    from ..textio import read_bytes, write_atomic

    fmt = program_format(args.program, args.format)  # -o as the input: refused before
    data = read_bytes(args.program, "program")
    try:
        text, encoding = data.decode("utf-8"), "utf-8"
    except UnicodeDecodeError:
        # bytes cp1252 leaves undefined (a GBK comment's 0x81) are kept as they were
        text, encoding = data.decode("cp1252", "surrogateescape"), "cp1252"
    # identify writes a robot file only once its audit passed; a file without that record
    # (calibrated_from) is not known to be a calibration
    verdict = (
        "passed (casecal identify wrote it after its audit)"
        if calibrated.calibrated_from
        else "unknown (the file records no calibration)"
    )
    header = calibration_header(args.robot, verdict) if os.path.isfile(args.robot) else None
    if header is not None:  # a file name the program's encoding cannot hold: '?' there
        header = header.encode(encoding, "replace").decode(encoding)
    orientation = False if args.position_only else None
    result = compensate_program(
        calibrated, text, fmt, nominal, header=header, frame=args.frame, orientation=orientation
    )
    if result.compensation is None and not result.skipped:
        raise CalibrationError(
            f"no joint targets found in {args.program!r} read as {fmt}; nothing written "
            "(check --format, and that the file is text in UTF-8 or Windows-1252)"
        )
    write_atomic(args.output, result.text.encode(encoding, "surrogateescape"))
    if args.json:
        left = [{"line": line, "reason": reason} for line, reason in result.skipped]
        write_json(args.json, _summary(args, len(result.changed) + len(left), left))
    say(f"wrote {args.output}: {len(result.changed)} target(s) compensated")
    for line, reason in result.skipped:
        say(f"  line {line} left as it was: {reason}")


def _summary(args: argparse.Namespace, targets: int, left: list) -> dict:
    """--json: ``schema``, ``output``, ``targets``, ``corrected`` and ``left`` (each with
    its CSV ``row`` (0-based) or program ``line`` (1-based) and ``reason``)."""
    return {
        "schema": "casecal.compensation/1",
        "output": args.output,
        "targets": targets,
        "corrected": targets - len(left),
        "left": left,
    }
