"""``casecal robots`` and ``casecal show``: the catalog, and a robot's table in mm and
degrees."""

from __future__ import annotations

import argparse
import math

from ..model.catalog import load_robot, robots
from ..model.parameters import unit
from .common import add_robot_options, command, robot_for


def add_parser(sub) -> None:
    """Register ``robots`` and ``show`` on the subcommand action `sub`."""
    p = command(
        sub,
        "robots",
        help="list the robot catalog (name, dof, joint types, source)",
        description="List the robots in casecal's catalog.",
    )
    p.add_argument("--wide", action="store_true", help="do not shorten the source column")
    p.set_defaults(func=run_robots)

    p = command(
        sub,
        "show",
        help="print a robot's DH table in mm and degrees",
        description="Print the DH table (theta, d, a, alpha, Hayati beta, joint limits) of a "
        "catalog robot or a robot TOML file, in mm and degrees, with its source.",
    )
    p.add_argument(
        "robot", metavar="NAME|FILE", help="catalog name (e.g. scorbot), .toml or .urdf path"
    )
    add_robot_options(p)
    p.set_defaults(func=run)


def run_robots(args: argparse.Namespace) -> None:
    """``casecal robots``: one line per catalog robot."""
    rows = []
    for name in robots():
        robot = load_robot(name)  # no note about namesakes here: nobody typed the name
        source = robot.source[0] if robot.source else ""
        rows.append(
            (name, str(robot.dof), robot.joint_types, robot.convention, robot.full_name, source)
        )
    header = ("name", "dof", "joints", "conv", "robot", "source (first of several)")
    widths = [max(len(r[k]) for r in [header, *rows]) for k in range(5)]
    for row in [header, *rows]:
        cells = [c.ljust(w) for c, w in zip(row[:5], widths, strict=True)]
        src = row[5] if args.wide or len(row[5]) <= 60 else row[5][:57] + "..."
        print("  ".join([*cells, src]).rstrip())


def run(args: argparse.Namespace) -> None:
    """``casecal show``: the robot's parameters, frames, sources and coupling."""
    robot = robot_for(args, args.robot)
    deg, mm = 180.0 / math.pi, 1e3
    if robot.convention == "urdf":
        _show_urdf(robot, deg, mm)
        _show_coupling(robot, deg, mm)
        return
    conv = "standard DH" if robot.convention == "dh" else "modified DH (Craig)"
    print(f"{robot.name}: {robot.full_name or robot.name}")
    joints = "1 joint" if robot.model_dof == 1 else f"{robot.model_dof} joints"
    print(f"{joints} ({robot.joint_types}), {conv}; lengths in mm, angles in degrees")
    print()
    print(
        f"{'joint':>5} {'type':>4} {'theta':>10} {'d':>10} {'a':>10} {'alpha':>10} "
        f"{'beta':>10} {'q min':>10} {'q max':>10}"
    )
    for i, j in enumerate(robot.joints, start=1):
        beta = _fmt(j.beta * deg) if j.beta is not None else f"{'-':>10}"
        if j.limits is None:
            lim = f"{'(none)':>10} {'':>10}"
        else:
            scale = deg if j.type == "R" else mm
            lim = f"{_fmt(j.limits[0] * scale)} {_fmt(j.limits[1] * scale)}"
        q_unit = "" if j.type == "R" else "  (q min/max in mm)"
        print(
            f"{i:>5} {j.type:>4} {_fmt(j.theta * deg)} {_fmt(j.d * mm)} {_fmt(j.a * mm)} "
            f"{_fmt(j.alpha * deg)} {beta} {lim}{q_unit}"
        )
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
    _show_coupling(robot, deg, mm)


def _show_coupling(robot, deg: float, mm: float) -> None:
    """The joint coupling, if any: which joint values the robot takes."""
    c = robot.coupling
    if c is None:
        return
    print(
        f"joint coupling: the controller's {robot.dof} joints (CSV q1 … q{robot.dof}) drive "
        f"the model's {robot.model_dof}:"
    )
    for line in c.describe(robot.joint_types):
        print(f"  {line}")
    if c.square:
        print("  (q min / q max above bound the controller joints)")
        return
    for k, j in enumerate(robot.controller_joints, start=1):
        scale, u = (deg, "deg") if j.type == "R" else (mm, "mm")
        lim = "none"
        if j.limits is not None:
            lim = f"{j.limits[0] * scale:.4f} … {j.limits[1] * scale:.4f} {u}"
        print(f"  controller q{k} ({j.type}) limits: {lim}")


def _show_urdf(robot, deg: float, mm: float) -> None:
    print(f"{robot.name}: {robot.full_name or robot.name}")
    joints = "1 joint" if robot.dof == 1 else f"{robot.dof} joints"
    print(f"{joints} ({robot.joint_types}), URDF joint origins; mm and degrees")
    print()
    print(
        f"{'joint':<24} {'type':>4} {'x':>10} {'y':>10} {'z':>10} "
        f"{'roll':>10} {'pitch':>10} {'yaw':>10}  axis"
    )
    for j in robot.joints:
        numbers = (
            " ".join(_fmt(v * mm) for v in j.xyz) + " " + " ".join(_fmt(v * deg) for v in j.rpy)
        )
        axis = ", ".join(f"{v:g}" for v in j.axis)
        parent = ""
        if robot.is_tree:
            k = robot.parents[robot.joints.index(j)]
            parent = f"  on {robot.joints[k].name if k >= 0 else 'the base'}"
        print(f"{j.name:<24} {j.type:>4} {numbers}  ({axis}){parent}")
    # a tree is measured at its tips, each with its frame, in place of the tool
    frames = [("base", robot.base)] + (
        [(f"tip {t.name} on {robot.joints[t.parent].name}", t) for t in robot.tip_frames]
        if robot.is_tree
        else [("tool", robot.tool)]
    )
    for label, frame in frames:
        xyz = ", ".join(f"{v * mm:.4f}" for v in frame.xyz)
        rpy = ", ".join(f"{v * deg:.4f}" for v in frame.rpy)
        print(f"{label}: xyz = ({xyz}) mm, rpy = ({rpy}) deg")


def _fmt(value: float, width: int = 10) -> str:
    return f"{value:{width}.4f}"
