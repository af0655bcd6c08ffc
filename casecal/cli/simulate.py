"""``casecal simulate`` and ``casecal observability``: a robot driven through a pose
schedule, measured (simulated) or judged for what it can identify."""

from __future__ import annotations

import argparse

import numpy as np

from ..data.files import write_csv
from ..data.measurements import simulate
from ..design import poses
from ..errors import CalibrationError
from ..identification.analysis import observability
from ..model.catalog import load_deviations
from .common import (
    PARAMS_HELP,
    add_json_option,
    add_robot_options,
    command,
    parse_length,
    robot_for,
    say,
    write_json,
)


def add_schedule(p: argparse.ArgumentParser, default_poses: int) -> None:
    """--poses, --schedule and --seed."""
    p.add_argument(
        "--poses",
        type=int,
        default=default_poses,
        help=f"number of poses (default {default_poses})",
    )
    p.add_argument(
        "--schedule",
        choices=("seed", "uniform"),
        default="seed",
        help="seed: the paper's (all joints 0, 1, 2, ... degrees together); "
        "uniform: random inside the joint limits (default seed)",
    )
    p.add_argument(
        "--seed",
        type=int,
        default=0,
        help="random seed for uniform poses and noise (default 0)",
    )


def add_parser(sub) -> None:
    """Register ``simulate`` and ``observability`` on the subcommand action `sub`."""
    p = command(
        sub,
        "simulate",
        help="simulate position measurements of a robot with deviations",
        description="Simulate measured tool-point positions of a robot whose parameters "
        "deviate from nominal, and write them as CSV (joints in deg/mm, positions in mm).",
    )
    p.add_argument(
        "robot", metavar="ROBOT", help="catalog name, .toml or .urdf path (the nominal robot)"
    )
    add_schedule(p, 100)
    p.add_argument(
        "--deviations",
        metavar="FILE",
        help="TOML of deviations: length_unit, angle_unit and name = value lines "
        '(e.g. theta1 = 0.01 with angle_unit = "deg")',
    )
    p.add_argument(
        "--noise",
        default="0mm",
        help="Gaussian noise sigma per coordinate, e.g. 0.01mm or 10um "
        "(bare numbers are mm; default 0)",
    )
    p.add_argument("-o", "--output", required=True, metavar="CSV", help="measurement file to write")
    add_robot_options(p)
    p.set_defaults(func=run)

    p = command(
        sub,
        "observability",
        help="what a pose set can identify, and what it cannot",
        description="Rank, identifiable and unidentifiable parameters, blind combinations in "
        "words, and observability indices O1-O5 of a pose schedule.",
    )
    p.add_argument("robot", metavar="ROBOT", help="catalog name, .toml or .urdf path")
    add_schedule(p, 100)
    p.add_argument("--parameters", default=None, help=PARAMS_HELP)
    add_robot_options(p)
    add_json_option(p)
    p.set_defaults(func=run_observability)


def schedule(robot, args):
    """The joint values of --poses, --schedule and --seed."""
    if args.poses < 1:
        raise CalibrationError(f"--poses must be at least 1, got {args.poses}")
    if args.schedule == "seed":
        return poses.seed_schedule(robot, args.poses)
    return poses.uniform(robot, args.poses, seed=args.seed)


def run(args: argparse.Namespace) -> None:
    """``casecal simulate``: the measurement CSV of a robot with deviations."""
    robot = robot_for(args, args.robot)
    deviations = load_deviations(args.deviations, robot) if args.deviations else {}
    true = robot.with_deviations(deviations)
    q = schedule(robot, args)
    meas = simulate(true, q, noise=parse_length(args.noise), seed=args.seed)
    # every measured point of every pose (a robot may carry several reflectors)
    shift = np.linalg.norm(meas.points - robot.measured_points(meas.q), axis=-1)
    write_csv(args.output, meas, robot)
    each = f", {shift.shape[1]} points each" if shift.shape[1] > 1 else ""
    say(
        f"wrote {meas.n_poses} poses{each} of {robot.name} ({args.schedule} schedule) "
        f"to {args.output}"
    )
    say(
        f"{len(deviations)} deviations, noise sigma {parse_length(args.noise) * 1e3:g} mm; "
        f"measured minus nominal: RMS {np.sqrt(np.mean(shift**2)) * 1e3:.4f} mm, "
        f"max {shift.max() * 1e3:.4f} mm"
    )


def run_observability(args: argparse.Namespace) -> None:
    """``casecal observability``: what a pose schedule can identify."""
    robot = robot_for(args, args.robot)
    q = schedule(robot, args)
    obs = observability(robot, q, args.parameters)
    print(f"{robot.name}, {args.schedule} schedule, {args.poses} poses")
    print(obs)
    if args.json:
        from ..identification.result_dict import observability_dict

        write_json(args.json, observability_dict(obs))
