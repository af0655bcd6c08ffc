"""``casecal calibrate-until``: the fewest measured poses that reach an error threshold."""

from __future__ import annotations

import argparse

from ..data.files import read_csv
from ..errors import CalibrationError
from .common import (
    PARAMS_HELP,
    ROBOT_OUT_HELP,
    add_robot_options,
    command,
    parse_length,
    robot_for,
    say,
)
from .writing import (
    add_sizes,
    check_robot_format,
    with_sizes,
    without_poorly_determined,
    write_calibrated,
)


def add_parser(sub) -> None:
    """Register ``calibrate-until`` on the subcommand action `sub`."""
    p = command(
        sub,
        "calibrate-until",
        help="use the fewest measured poses that reach an error threshold",
        description="From a pool of measured poses (CSV), take poses in batches (D-optimal "
        "given those already taken, the paper's order, or uniform), identify after each "
        "batch, and stop when the predicted 95 % position error on new poses is under the "
        "threshold. Prints how many poses it took.",
    )
    p.add_argument(
        "robot", metavar="ROBOT", help="catalog name, .toml or .urdf path (nominal robot)"
    )
    p.add_argument("pool", metavar="CSV", help="measured poses to choose from")
    p.add_argument(
        "--threshold", default="0.1mm", help="predicted 95 %% error to reach (default 0.1mm)"
    )
    p.add_argument("--batch", type=int, default=5, help="poses per round (default 5)")
    p.add_argument("--max-poses", type=int, default=300, help="stop here (default 300)")
    p.add_argument(
        "--order",
        choices=("optimal", "seed", "uniform"),
        default="optimal",
        help="how to choose the next poses (default optimal)",
    )
    p.add_argument("--parameters", default=None, help=PARAMS_HELP)
    add_sizes(p)
    add_robot_options(p)
    p.add_argument("-o", "--output", metavar="FILE", help=ROBOT_OUT_HELP)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> None:
    """``casecal calibrate-until``: batches of the pool's poses until the target is reached."""
    from ..design.campaign import calibrate_until, pool_measure

    robot = with_sizes(robot_for(args, args.robot), args)
    pool = read_csv(args.pool, robot)
    if args.output:
        check_robot_format(args, robot)
    candidates, measure = pool_measure(pool)
    run = calibrate_until(
        robot,
        measure,
        parse_length(args.threshold),
        batch=args.batch,
        max_poses=min(args.max_poses, pool.n_poses),
        order=args.order,
        parameters=args.parameters,
        candidates=candidates,
    )
    say(run)
    say()
    say(run.calibration.summary())
    if not run.reached:
        raise CalibrationError(
            f"the pool's poses did not reach {args.threshold} (predicted "
            f"{run.predicted * 1e3:.3f} mm); nothing written"
        )
    cal = without_poorly_determined(run.calibration, run.measurements, {}, strict=False)
    write_calibrated(args, cal.robot)
