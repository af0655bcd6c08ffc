"""``casecal compensate``: corrected joint targets from a calibrated robot file (a leaf of
the command line, kept apart from cli.py's other commands)."""

from __future__ import annotations

import argparse
import io

import numpy as np


def add_command(command) -> None:
    """Register ``compensate`` with `command(name, **kwargs)` (cli.build_parser's helper)."""
    p = command(
        "compensate",
        help="correct joint targets so the real robot reaches where the nominal one would",
        description="Read joint targets (columns q1_deg ... or q1 ...) that a controller "
        "sends to the nominal robot, and write the joint values that bring the calibrated "
        "robot's tool to the same pose (its position for arms of fewer than six joints), "
        "in the robot's own base frame. One row out per row in, in degrees (mm for "
        "prismatic joints), with ok = 0 and a reason where a target cannot be corrected "
        "(singular, no convergence, outside the joint limits): those rows keep the target.",
    )
    p.add_argument("robot", metavar="CALIBRATED", help="calibrated robot file (.toml or .urdf)")
    p.add_argument("targets", metavar="CSV", help="joint targets ('-' for standard input)")
    p.add_argument("-o", "--output", required=True, metavar="CSV", help="file to write")
    p.add_argument(
        "--nominal",
        metavar="ROBOT",
        help="the robot the controller believes (default: calibrated_from in the file)",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> None:
    from . import cli
    from .data.files import read_joints, read_table
    from .model.compensate import compensate
    from .textio import write_atomic

    calibrated = cli.robot_for(args, args.robot)
    nominal = cli.robot_for(args, args.nominal) if args.nominal else None
    df, label = read_table(args.targets, "targets file")
    q = read_joints(df, calibrated, label)
    result = compensate(calibrated, q, nominal)
    columns = {}
    for i, joint in enumerate(calibrated.joints, start=1):
        scale, unit = (180 / np.pi, "deg") if joint.type == "R" else (1e3, "mm")
        columns[f"q{i}_{unit}"] = result.q[:, i - 1] * scale
    columns["ok"] = result.ok.astype(int)
    columns["position_error_mm"] = result.position_error * 1e3
    columns["reason"] = list(result.reason)
    import pandas as pd

    buffer = io.StringIO()
    pd.DataFrame(columns).to_csv(buffer, index=False, float_format="%.17g")
    write_atomic(args.output, buffer.getvalue())
    cli.WRITTEN.append(str(args.output))
    bad = int((~result.ok).sum())
    print(
        f"wrote {len(q)} corrected targets to {args.output}"
        + (
            f"; {bad} could not be corrected (ok = 0, reason given; they keep the target)"
            if bad
            else ""
        )
    )
