"""``casecal convert``: a robot file in another format, without refitting anything."""

from __future__ import annotations

import argparse
import dataclasses

from ..errors import CalibrationError
from ..textio import write_atomic
from .common import add_robot_options, command, robot_for, say
from .writing import how_to_load, nominal_seen_from, say_notes


def add_parser(sub) -> None:
    """Register ``convert`` on the subcommand action `sub`."""
    p = command(
        sub,
        "convert",
        help="write a robot file in another format (TOML, URDF, UR kinematics YAML)",
        description="Read a robot (catalog name, .toml, .urdf, .xacro or a UR calibration "
        ".yaml) and write it in the format OUT's extension names (.toml, .urdf, .yaml), "
        "nothing refitted. The written text is read back and its forward kinematics "
        "compared with the robot's at 300 poses before it replaces anything, as every "
        "export is; a conversion that cannot be exact (a joint coupling or error terms to "
        "URDF, a tree to a UR file, a tool a UR file cannot place) is refused, nothing "
        "written. OUT may not be the robot file read; an existing OUT is replaced only if "
        "casecal wrote it (or with --overwrite). A calibrated robot's link to its nominal "
        "robot (calibrated_from) is kept, relative to OUT's folder.",
    )
    p.add_argument("robot", metavar="IN", help="catalog name, .toml, .urdf, .xacro or .yaml path")
    p.add_argument(
        "out", metavar="OUT", help="file to write: .toml, .urdf or .yaml (UR kinematics)"
    )
    add_robot_options(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> None:
    """``casecal convert``: load IN, export it checked to OUT, refuse any loss."""
    from ..model.save import export

    if not args.out.strip():
        raise CalibrationError("the output file name is empty; give a file name as OUT")
    robot = robot_for(args, args.robot)
    if robot.calibrated_from:  # loading made it a path from here: from OUT's folder now
        robot = dataclasses.replace(
            robot, calibrated_from=nominal_seen_from(robot.calibrated_from, args.out)
        )
    out = export(robot, args.out)  # read back and compared before anything is written
    if out.statement:
        raise CalibrationError(
            f"{args.out}: {out.statement}; not written: convert writes exact copies only "
            "(convert to .toml, which holds everything)"
        )
    say_notes(args.out, out)
    write_atomic(args.out, out.text)
    say(f"{robot.name} written to {args.out} ({how_to_load(args.out, robot)})")
