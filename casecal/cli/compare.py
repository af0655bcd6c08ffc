"""``casecal compare``: which error model the data support (one module of `casecal.cli`)."""

from __future__ import annotations

import argparse
import dataclasses

from .common import add_json_option, add_robot_options, command, robot_for, write_json


def add_parser(sub) -> None:
    """Register ``compare`` on the subcommand action `sub`."""
    p = command(
        sub,
        "compare",
        help="fit nested error models and say which the data support (cross-validation)",
        description="Fit the rigid robot, then with gravity compliance (--compliance), then "
        "with joint-angle harmonics (--harmonics), each to the same poses with all its "
        "parameters, and print per model the parameters estimated, in-sample and k-fold "
        "cross-validated RMS (mm per point) and AIC/BIC. The chosen model has the fewest "
        "parameters within one standard error of the best cross-validated RMS.",
    )
    p.add_argument("robot", metavar="ROBOT", help="catalog name, .toml or .urdf path")
    p.add_argument("measurements", metavar="CSV", help="measurement file")
    p.add_argument(
        "--compliance",
        action="store_true",
        help="add gravity compliance on every loaded joint (c_i with masses in the robot "
        "file, lumped terms without; then also the lumped terms that predict, chosen again "
        "in each fold)",
    )
    p.add_argument(
        "--harmonics",
        action="append",
        default=[],
        metavar="JOINT:ORDER",
        help="add harmonics of a joint's angle up to ORDER (repeatable), e.g. 2:2",
    )
    p.add_argument("--folds", type=int, default=5, help="cross-validation folds (default 5)")
    add_json_option(p)
    add_robot_options(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> None:
    """``casecal compare``: fit the nested models and print the comparison table."""
    from ..data.files import read_csv
    from ..errors import CalibrationError
    from ..identification.compare import compare_models
    from ..identification.lumped_select import ReducedLumped

    robot = robot_for(args, args.robot)
    rigid = dataclasses.replace(robot, terms=(), auto_beta=False)
    models = {"rigid": rigid}
    current = rigid
    if args.compliance:
        current = current.with_compliance()
        models["+ compliance"] = current
    for spec in args.harmonics:
        try:
            joint, order = (int(v) for v in spec.split(":"))
        except ValueError:
            raise CalibrationError(f"--harmonics {spec!r}: give JOINT:ORDER, e.g. 2:2") from None
        current = current.with_joint_harmonics(joint, order)
        models[f"+ harmonics {joint}:{order}"] = current
    if len(models) == 1:
        raise CalibrationError("nothing to compare: add --compliance and/or --harmonics J:K")
    meas = read_csv(args.measurements, robot)
    lumped = any(t.kind == "lumped_compliance" for t in models.get("+ compliance", rigid).terms)
    if lumped and meas.session is None and not getattr(meas, "contact", None):
        # the lumped terms that predict, beside all of them (chosen again in each fold)
        names = list(models)
        at = names.index("+ compliance") + 1
        extra = {"+ compliance, terms that predict": ReducedLumped(rigid)}
        models = {n: models[n] for n in names[:at]} | extra | {n: models[n] for n in names[at:]}
    comparison = compare_models(models, meas, folds=args.folds)
    print(comparison)
    if args.json:
        from ..identification.result_dict import comparison_dict

        write_json(args.json, comparison_dict(comparison))
