"""``casecal validate``: a calibrated robot's errors on held-out measurements."""

from __future__ import annotations

import argparse

from ..data.files import read_csv
from ..errors import CalibrationError
from ..identification.result_dict import validation_dict
from ..identification.validation import validate
from ..model.catalog import nominal_of
from .common import add_json_option, add_robot_options, command, robot_for, write_json


def add_parser(sub) -> None:
    """Register ``validate`` on the subcommand action `sub`."""
    p = command(
        sub,
        "validate",
        help="errors of a calibrated robot on held-out measurements",
        description="Refit only the frames (base, tool, reflectors: the instrument may have "
        "moved) of the nominal and the calibrated robot to held-out measurements and print "
        "RMS, mean and max position error before and after calibration, in mm.",
    )
    p.add_argument("calibrated", metavar="CALIBRATED.toml", help="written by casecal identify -o")
    p.add_argument("measurements", metavar="CSV", help="held-out measurements")
    p.add_argument(
        "--nominal",
        metavar="ROBOT",
        help="the nominal robot (default: calibrated_from in the TOML)",
    )
    add_json_option(p)
    add_robot_options(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> None:
    """``casecal validate``: errors before and after calibration on held-out poses."""
    calibrated = robot_for(args, args.calibrated)
    nominal_name = args.nominal or calibrated.calibrated_from
    if not nominal_name:
        raise CalibrationError(
            f"{args.calibrated} does not say which robot it was calibrated from; give --nominal"
        )
    nominal = robot_for(args, nominal_name) if args.nominal else nominal_of(calibrated)
    if (
        nominal.structure.names[: len(nominal.parameter_names)]
        != calibrated.parameter_names[: len(nominal.parameter_names)]
    ):
        raise CalibrationError(f"{nominal_name} and {args.calibrated} are different robots")
    meas = read_csv(args.measurements, calibrated)
    result = validate(calibrated, meas, nominal)
    print(result)
    if args.json:
        write_json(args.json, validation_dict(result))
