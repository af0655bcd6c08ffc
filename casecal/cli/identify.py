"""``casecal identify``: the parameter deviations of a robot from its measurements."""

from __future__ import annotations

import argparse

from ..data.files import read_csv
from ..errors import CalibrationError
from ..identification.fit import DEFAULT_METHOD, METHODS, identify
from ..identification.validation import split, validate
from ..model.catalog import load_deviations
from ..textio import write_together
from .common import (
    PARAMS_HELP,
    ROBOT_OUT_HELP,
    add_robot_options,
    command,
    json_text,
    parse_angle,
    parse_length,
    robot_for,
    say,
)
from .identify_modes import add_modes, identify_camera, identify_distances
from .writing import (
    add_sizes,
    check_fit,
    check_robot_format,
    progress_line,
    with_sizes,
    without_poorly_determined,
    write_outputs,
)


def add_parser(sub) -> None:
    """Register ``identify`` on the subcommand action `sub`."""
    p = command(
        sub,
        "identify",
        help="identify parameter deviations from a measurement CSV",
        description="Identify the parameter deviations of ROBOT from measured positions, print "
        "a summary (mm, degrees) with standard errors and what the data cannot see, and "
        "optionally write the calibrated robot (-o: TOML, URDF or UR kinematics YAML by its "
        "extension).",
    )
    p.add_argument(
        "robot", metavar="ROBOT", help="catalog name, .toml or .urdf path (nominal robot)"
    )
    p.add_argument(
        "measurements",
        metavar="CSV",
        help="one row per pose: q1..qn (or q1_deg, q3_mm), x, y, z (or x_mm...); an "
        "optional session column labels the instrument's placements, each fitted with its "
        "own base frame",
    )
    _add_fit_options(p)
    p.add_argument(
        "--deviations-out",
        metavar="FILE",
        help="write deviations and standard errors as .json or .csv",
    )
    _add_result_options(p)
    add_modes(p)
    p.add_argument(
        "--per-session",
        choices=("base", "base,tool"),
        default=None,
        help="with a session column: the frames each session has of its own (default base; "
        "base,tool when the probe was re-mounted too)",
    )
    p.add_argument(
        "--strict",
        action="store_true",
        help="fail (exit 2, nothing written) if any asked-for parameter cannot be identified, "
        "instead of holding it at nominal and saying so",
    )
    add_sizes(p)
    add_robot_options(p)
    p.add_argument("-o", "--output", metavar="FILE", help=ROBOT_OUT_HELP)
    p.set_defaults(func=run)


def _add_result_options(p: argparse.ArgumentParser) -> None:
    """--json, --residuals, --plot: the result for scripts and for the eye, written
    whether or not the fit passed (they say so), before -o's check."""
    p.add_argument(
        "--json",
        metavar="FILE",
        help="write the whole result as one JSON object (keys in the README: verdict, "
        "errors in mm, each parameter in its unit, audit checks); '-' for standard output",
    )
    p.add_argument(
        "--residuals",
        metavar="CSV",
        help="write one row per measured point: pose, error before and after in mm, outlier",
    )
    p.add_argument(
        "--plot",
        metavar="PNG",
        help="draw the residuals: by pose, their distribution, by joint value; the poses that "
        "stand out marked",
    )


def _result_files(args: argparse.Namespace, cal, q) -> list:
    """(path, text or bytes) of --json, --residuals and --plot."""
    files = []
    if args.json:
        files.append((args.json, json_text(cal.to_dict())))
    if args.residuals:
        table = cal.residual_table()
        files.append((args.residuals, table.to_csv(index=False, float_format="%.9g")))
    if args.plot:
        import io

        from ..report.common import plt
        from ..report.residual_plot import residual_figure

        figure, buffer = residual_figure(cal, q), io.BytesIO()
        try:
            figure.savefig(buffer, format="png", dpi=150)
        finally:
            plt.close(figure)
        files.append((args.plot, buffer.getvalue()))
    return files


def _add_fit_options(p: argparse.ArgumentParser) -> None:
    """How identify fits: method, parameters, weights, hold-out and robust loss."""
    p.add_argument(
        "--method",
        choices=METHODS,
        default=DEFAULT_METHOD,
        help="gauss-newton, lm: iterated least squares; ipopt: CasADi NLP; svd: the "
        f"paper's one-shot linearised step (default {DEFAULT_METHOD})",
    )
    p.add_argument("--parameters", default=None, help=PARAMS_HELP)
    p.add_argument(
        "--noise",
        default=None,
        help="measurement sigma to weight with, e.g. 0.02mm (default: the file's "
        "sigma column, else unweighted)",
    )
    p.add_argument(
        "--truth",
        metavar="FILE",
        help="TOML of the true deviations (simulations): adds error columns",
    )
    p.add_argument("--max-iterations", type=int, default=100, help="for iterated methods")
    p.add_argument(
        "--holdout",
        type=float,
        default=None,
        metavar="FRACTION",
        help="keep this fraction of the poses out of the fit and report the "
        "errors on them before and after calibration (e.g. 0.2)",
    )
    p.add_argument("--seed", type=int, default=0, help="random seed of --holdout (default 0)")
    p.add_argument(
        "--loss",
        choices=("linear", "huber", "soft_l1"),
        default="linear",
        help="robust loss for data with outliers (default linear: least squares)",
    )
    p.add_argument(
        "--loss-scale",
        type=float,
        default=3.0,
        help="robust loss scale, in units of sigma (default 3)",
    )
    p.add_argument(
        "--orientation-sigma",
        metavar="ANGLE",
        help="sigma of measured orientations (qw..qz columns), e.g. 0.01deg",
    )


def run(args: argparse.Namespace) -> None:
    """``casecal identify``: fit, print the summary, write what -o and the others name."""
    robot = with_sizes(robot_for(args, args.robot), args)
    asked = [f for f, v in (("--json", args.json), ("--residuals", args.residuals),
                            ("--plot", args.plot)) if v]  # fmt: skip
    if asked and (args.camera or args.pairs):
        raise CalibrationError(
            f"{', '.join(asked)} are for measured points; with --camera or --pairs, use "
            "--deviations-out and the printed summary"
        )
    if args.camera:
        return identify_camera(args, robot)
    for flag, value in (("--sigma-px", args.sigma_px), ("--camera-out", args.camera_out)):
        if value is not None:
            raise CalibrationError(f"{flag} needs --camera (a camera measurement file)")
    if args.pairs:
        unsupported = [
            flag
            for flag, value in (
                ("--holdout", args.holdout),
                ("--strict", args.strict),
                ("--loss", args.loss != "linear"),
                ("--deviations-out", args.deviations_out),
                ("--orientation-sigma", args.orientation_sigma),
                ("--truth", args.truth),
                ("--noise", args.noise),
                ("--method ipopt", args.method == "ipopt"),
                ("--per-session", args.per_session),
            )
            if value
        ]
        if unsupported:
            raise CalibrationError(
                f"{', '.join(unsupported)} cannot be used with --pairs (distance measurements)"
            )
        return identify_distances(args, robot)
    meas = read_csv(args.measurements, robot)
    check_robot_format(args, robot)
    noise = parse_length(args.noise) if args.noise is not None else None
    truth = load_deviations(args.truth, robot) if args.truth else None
    held = None
    if args.holdout:
        if meas.contact:  # validate measures positions: refused before any fit or file
            raise CalibrationError(
                "--holdout cannot validate contact sessions (fixed points, planes): their "
                "held-out errors are not positions; leave --holdout out (the summary gives "
                "the contacts' residuals), or hold out a session of measured points"
            )
        meas, held = split(meas, args.holdout, seed=args.seed)
    rot = parse_angle(args.orientation_sigma) if args.orientation_sigma else None
    options = dict(
        noise=noise,
        truth=truth,
        max_iterations=args.max_iterations,
        loss=args.loss,
        loss_scale=args.loss_scale,
        orientation_sigma=rot,
        progress=progress_line(meas.n_poses),
    )
    progress = options["progress"]
    if args.per_session:
        options["per_session"] = tuple(args.per_session.split(","))
    cal = identify(robot, meas, args.parameters, args.method, **options)
    if progress is not None:
        progress.end()  # a terminal's rewritten line
    say(cal.summary())
    results = _result_files(args, cal, meas.q)
    if results:  # a failed fit's too: they describe it, they are no calibration
        write_together(results)
        say("result written to " + ", ".join(path for path, _ in results))
    check_fit(cal, args.strict, "poses")
    cal = without_poorly_determined(cal, meas, options, args.strict)
    # what was asked to be written is written as soon as the fit is good
    write_outputs(args, cal)
    if held is not None:
        print(f"\nValidation on {held.n_poses} held-out poses (--holdout {args.holdout}):")
        try:
            print(validate(cal.robot, held, robot))
        except CalibrationError as exc:
            written = " (the calibrated files above were written)" if args.output else ""
            raise CalibrationError(f"hold-out validation failed{written}: {exc}") from None
