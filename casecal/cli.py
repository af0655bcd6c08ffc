"""The ``casecal`` command: thin wrappers that parse, call the library and print.

Exit codes: 0 success, 2 a user error (one line on stderr), 1 a bug (traceback).
"""

from __future__ import annotations

import argparse
import logging
import math
import sys

from . import __version__
from .catalog import load_robot, robots
from .errors import CalibrationError
from .parameters import unit


def _cmd_robots(args: argparse.Namespace) -> None:
    rows = []
    for name in robots():
        robot = load_robot(name)
        source = robot.source[0] if robot.source else ""
        rows.append((name, str(robot.dof), robot.joint_types, robot.convention,
                     robot.full_name, source))  # fmt: skip
    header = ("name", "dof", "joints", "conv", "robot", "source (first of several)")
    widths = [max(len(r[k]) for r in [header, *rows]) for k in range(5)]
    for row in [header, *rows]:
        cells = [c.ljust(w) for c, w in zip(row[:5], widths, strict=True)]
        src = row[5] if args.wide or len(row[5]) <= 60 else row[5][:57] + "..."
        print("  ".join([*cells, src]).rstrip())


def _fmt(value: float, width: int = 10) -> str:
    return f"{value:{width}.4f}"


def _cmd_show(args: argparse.Namespace) -> None:
    robot = load_robot(args.robot)
    deg, mm = 180.0 / math.pi, 1e3
    conv = "standard DH" if robot.convention == "dh" else "modified DH (Craig)"
    print(f"{robot.name}: {robot.full_name or robot.name}")
    print(f"{robot.dof} joints ({robot.joint_types}), {conv}; lengths in mm, angles in degrees")
    print()
    print(f"{'joint':>5} {'type':>4} {'theta':>10} {'d':>10} {'a':>10} {'alpha':>10} "
          f"{'beta':>10} {'q min':>10} {'q max':>10}")  # fmt: skip
    for i, j in enumerate(robot.joints, start=1):
        beta = _fmt(j.beta * deg) if j.beta is not None else f"{'-':>10}"
        if j.limits is None:
            lim = f"{'(none)':>10} {'':>10}"
        else:
            scale = deg if j.type == "R" else mm
            lim = f"{_fmt(j.limits[0] * scale)} {_fmt(j.limits[1] * scale)}"
        q_unit = "" if j.type == "R" else "  (q min/max in mm)"
        print(f"{i:>5} {j.type:>4} {_fmt(j.theta * deg)} {_fmt(j.d * mm)} {_fmt(j.a * mm)} "
              f"{_fmt(j.alpha * deg)} {beta} {lim}{q_unit}")  # fmt: skip
    for label, frame in (("base", robot.base), ("tool", robot.tool)):
        xyz = ", ".join(f"{v * mm:.4f}" for v in frame.xyz)
        rpy = ", ".join(f"{v * deg:.4f}" for v in frame.rpy)
        print(f"{label}: xyz = ({xyz}) mm, rpy = ({rpy}) deg")
    betas = [n for n in robot.parameter_names if n.startswith("beta")]
    if betas:
        print(
            f"Hayati beta on {', '.join(betas)}: consecutive axes are parallel there, "
            "so d alone is ill-defined."
        )
    n_params = len(robot.parameter_names)
    lengths = sum(unit(n) == "m" for n in robot.parameter_names)
    print(f"{n_params} geometric parameters ({lengths} lengths, {n_params - lengths} angles).")
    if robot.source:
        print("source:")
        for s in robot.source:
            print(f"  - {s}")
    if robot.confidence:
        print(f"confidence: {robot.confidence}")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``casecal`` command."""
    parser = argparse.ArgumentParser(
        prog="casecal",
        description="Kinematic calibration of serial robot arms: robot models with exact "
        "parameter Jacobians (CasADi), identification of DH errors from measured positions.",
        epilog="Robots are catalog names (see 'casecal robots') or paths to robot TOML files. "
        "Lengths print in mm, angles in degrees.",
    )
    parser.add_argument("--version", action="version", version=f"casecal {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0,
                        help="log what the library does (-vv for debug detail)")  # fmt: skip
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    p = sub.add_parser("robots", help="list the robot catalog (name, dof, joint types, source)",
                       description="List the robots in casecal's catalog.")  # fmt: skip
    p.add_argument("--wide", action="store_true", help="do not shorten the source column")
    p.set_defaults(func=_cmd_robots)

    p = sub.add_parser(
        "show",
        help="print a robot's DH table in mm and degrees",
        description="Print the DH table (theta, d, a, alpha, Hayati beta, joint limits) of a "
        "catalog robot or a robot TOML file, in mm and degrees, with its source.",
    )
    p.add_argument("robot", metavar="NAME|FILE", help="catalog name (e.g. scorbot) or .toml path")
    p.set_defaults(func=_cmd_show)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the ``casecal`` command; returns the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    level = {0: logging.WARNING, 1: logging.INFO}.get(args.verbose, logging.DEBUG)
    logging.basicConfig(level=level, format="casecal: %(levelname)s: %(message)s")
    try:
        args.func(args)
    except CalibrationError as exc:
        print(f"casecal: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # e.g. `casecal robots | head`
        return 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
