"""The ``casecal`` command: thin wrappers that parse, call the library and print.

Exit codes: 0 success, 2 a user error (one line on stderr), 1 a bug (traceback).
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import math
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from . import __version__, cli_args
from ._signals import sigterm_unwinds
from .data.files import read_csv, write_atomic, write_csv, write_together
from .data.measurements import simulate
from .design import poses
from .errors import CalibrationError, Terminated
from .identification.analysis import observability
from .identification.fit import DEFAULT_METHOD, METHODS, identify
from .identification.validation import split, validate
from .model.catalog import load_deviations, load_robot, nominal_of, robots
from .model.names import is_path, namesake_note, path_text
from .model.parameters import unit
from .textio import recording

_LENGTH_UNITS = {"m": 1.0, "mm": 1e-3, "um": 1e-6}


def parse_length(text: str) -> float:
    """'0.01mm', '10um', '1e-5m' or a bare number (mm) to metres."""
    t = text.strip().lower().replace("µm", "um")
    for suffix in ("mm", "um", "m"):
        if t.endswith(suffix):
            number, scale = t[: -len(suffix)], _LENGTH_UNITS[suffix]
            break
    else:
        number, scale = t, 1e-3
    try:
        value = float(number) * scale
    except ValueError:
        raise CalibrationError(
            f"{text!r} is not a length; write e.g. 0.01mm, 10um or 1e-5m"
        ) from None
    if not math.isfinite(value) or value < 0:
        raise CalibrationError(f"{text!r} must be a finite, non-negative length")
    return value


def _schedule(robot, args):
    if args.poses < 1:
        raise CalibrationError(f"--poses must be at least 1, got {args.poses}")
    if args.schedule == "seed":
        return poses.seed_schedule(robot, args.poses)
    return poses.uniform(robot, args.poses, seed=args.seed)


def _cmd_simulate(args: argparse.Namespace) -> None:
    robot = robot_for(args, args.robot)
    if not args.output.strip():
        raise CalibrationError("the output file name is empty; give a file name with -o")
    _check_writable_dir(os.path.dirname(os.path.abspath(args.output)))
    deviations = load_deviations(args.deviations, robot) if args.deviations else {}
    true = robot.with_deviations(deviations)
    q = _schedule(robot, args)
    meas = simulate(true, q, noise=parse_length(args.noise), seed=args.seed)
    # every measured point of every pose (a robot may carry several reflectors)
    shift = np.linalg.norm(meas.points - robot.measured_points(meas.q), axis=-1)
    write_csv(args.output, meas, robot)
    each = f", {shift.shape[1]} points each" if shift.shape[1] > 1 else ""
    print(
        f"wrote {meas.n_poses} poses{each} of {robot.name} ({args.schedule} schedule) "
        f"to {args.output}"
    )
    print(
        f"{len(deviations)} deviations, noise sigma {parse_length(args.noise) * 1e3:g} mm; "
        f"measured minus nominal: RMS {np.sqrt(np.mean(shift**2)) * 1e3:.4f} mm, "
        f"max {shift.max() * 1e3:.4f} mm"
    )


def parse_angle(text: str) -> float:
    """'0.01deg', '1e-4rad' or a bare number (degrees) to radians."""
    t = text.strip().lower()
    scale, number = math.pi / 180, t
    if t.endswith("deg"):
        number = t[:-3]
    elif t.endswith("rad"):
        scale, number = 1.0, t[:-3]
    try:
        value = float(number) * scale
    except ValueError:
        raise CalibrationError(f"{text!r} is not an angle; write e.g. 0.01deg or 2e-4rad") from None
    if not math.isfinite(value) or value < 0:
        raise CalibrationError(f"{text!r} must be a finite, non-negative angle")
    return value


def _with_sizes(robot, args: argparse.Namespace):
    """`robot` with --plausible-length-mm and --plausible-angle-deg, over its file's."""
    length, angle = args.plausible_length_mm, args.plausible_angle_deg
    if length is None and angle is None:
        return robot
    return robot.with_plausible(
        length=None if length is None else length * 1e-3,
        angle=None if angle is None else math.radians(angle),
    )


def _cmd_identify(args: argparse.Namespace) -> None:
    robot = _with_sizes(robot_for(args, args.robot), args)
    if args.camera:
        return _identify_camera(args, robot)
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
        return _identify_distances(args, robot)
    meas = read_csv(args.measurements, robot)
    for out in (args.output, args.deviations_out):
        if out is not None and not out.strip():
            raise CalibrationError("an output file name is empty; give a file name")
        if out:  # fail before the work, not after it
            _check_writable_dir(os.path.dirname(os.path.abspath(out)))
    _check_robot_format(args, robot)
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
        progress=_progress_line(meas.n_poses),
    )
    if args.per_session:
        options["per_session"] = tuple(args.per_session.split(","))
    cal = identify(robot, meas, args.parameters, args.method, **options)
    if meas.n_poses >= PROGRESS_POSES and sys.stderr.isatty():
        print(file=sys.stderr)  # end the progress line
    print(cal.summary())
    _check_fit(cal, args.strict, "poses")
    cal = _without_poorly_determined(cal, meas, options, args.strict)
    # what was asked to be written is written as soon as the fit is good
    _write_outputs(args, cal)
    if held is not None:
        print(f"\nValidation on {held.n_poses} held-out poses (--holdout {args.holdout}):")
        try:
            print(validate(cal.robot, held, robot))
        except CalibrationError as exc:
            written = " (the calibrated files above were written)" if args.output else ""
            raise CalibrationError(f"hold-out validation failed{written}: {exc}") from None


def _check_fit(cal, strict: bool, what: str) -> None:
    """Refuse to write a fit that failed, or (--strict) one that left parameters blind."""
    if strict and cal.unidentifiable:
        raise CalibrationError(
            f"--strict: the data cannot identify {', '.join(cal.unidentifiable)}; ask for "
            f"fewer parameters or measure more varied {what} (nothing written)"
        )
    if not cal.success:
        raise CalibrationError(f"the fit did not pass ({cal.message}); nothing written")


def _without_poorly_determined(cal, meas, options, strict):
    """The calibration to write: poorly determined estimates held at nominal, the rest
    refitted (`casecal.identification.usable`); a refit that fails writes nothing."""
    from .identification.calibration import display_unit
    from .identification.usable import held_as_poorly_determined, hold_poorly_determined

    poorly = held_as_poorly_determined(cal)
    if not poorly:
        return cal
    shown = []
    for name in poorly:
        unit, factor = display_unit(name)
        shown.append(f"{name} ± {cal.standard_errors[name] * factor:.3g} {unit}")
    print(
        f"\n{', '.join(shown)}: poorly determined, so not written: held at nominal and the "
        "other parameters refitted without them. The calibration written:\n"
    )
    refit = hold_poorly_determined(cal, meas, **options)
    print(refit.summary())
    held = [n for n in cal.parameters if n not in refit.parameters]
    if not refit.success:
        raise CalibrationError(
            f"with {', '.join(held)} held at nominal the fit does not pass "
            f"({refit.message}); nothing written: measure more, better-spread poses, or "
            "leave these parameters out of --parameters"
        )
    if strict and refit.unidentifiable:
        raise CalibrationError(
            f"--strict: the data cannot identify {', '.join(refit.unidentifiable)}; ask for "
            "fewer parameters or measure more varied poses (nothing written)"
        )
    return refit


PROGRESS_POSES = 10_000
"""Fits of at least this many poses show their iterations on stderr as they go."""


def _progress_line(n_poses: int):
    """A callback that rewrites one stderr line per iteration, for long fits only."""
    if n_poses < PROGRESS_POSES:
        return None
    start = time.perf_counter()
    rewrite = sys.stderr.isatty()  # a log file gets one line per iteration

    def show(line: str) -> None:
        elapsed = time.perf_counter() - start
        text = f"casecal: {n_poses} poses, {line} ({elapsed:.1f} s)"
        print(f"\r{text}" if rewrite else text, end="" if rewrite else "\n", file=sys.stderr)

    return show


def _identify_distances(args: argparse.Namespace, robot) -> None:
    from .identification.distances import identify_distances, read_distance_csv

    if args.output:
        _check_writable_dir(os.path.dirname(os.path.abspath(args.output)))
    meas = read_distance_csv(args.measurements, args.pairs, robot)
    method = "gauss-newton" if args.method == "ipopt" else args.method
    cal = identify_distances(
        robot, meas, args.parameters, method, max_iterations=args.max_iterations
    )
    print(f"{meas.n_pairs} distances between {len(meas.q)} poses")
    print(cal.summary())
    if not cal.success:
        raise CalibrationError(f"the fit did not pass ({cal.message}); nothing written")
    _write_calibrated(args, cal.robot)


def _identify_camera(args: argparse.Namespace, robot) -> None:
    """identify --camera: the measurement file is a camera's (`casecal.observations.files`)."""
    from .observations.files import camera_text, read_cameras, read_pixels

    unsupported = [
        flag
        for flag, value in (
            ("--pairs", args.pairs),
            ("--loss", args.loss != "linear"),
            ("--orientation-sigma", args.orientation_sigma),
            ("--truth", args.truth),
            ("--noise (the pixel noise is --sigma-px)", args.noise),
            ("--per-session", args.per_session),
        )
        if value
    ]
    if unsupported:
        raise CalibrationError(f"{', '.join(unsupported)} cannot be used with --camera")
    if args.camera_out and not args.camera_out.lower().endswith(".toml"):
        raise CalibrationError(
            f"--camera-out {args.camera_out}: a camera file is TOML; name it .toml"
        )
    for out in (args.output, args.deviations_out, args.camera_out):
        if out is not None and not out.strip():
            raise CalibrationError("an output file name is empty; give a file name")
        if out:
            _check_writable_dir(os.path.dirname(os.path.abspath(out)))
    _check_robot_format(args, robot)
    sigma = None if args.sigma_px is None else float(args.sigma_px)
    setup, placements = read_cameras(args.camera)
    meas = read_pixels(args.measurements, robot, setup, sigma, sessions=placements)
    found = int(meas.found.sum())
    print(f"{meas.n_poses} views, {found} corners found of {meas.pixels.shape[1]} per view")
    held = None
    if args.holdout:
        meas, held = split(meas, args.holdout, seed=args.seed)
    cal = identify(robot, meas, args.parameters, args.method, max_iterations=args.max_iterations)
    print(cal.summary())
    print(
        f"RMS pixel error: {cal.camera.rms_px_before:.3g} px with the camera and board "
        f"poses alone fitted, {cal.camera.rms_px:.3g} px calibrated (sigma {meas.sigma_px:g} px)"
    )
    _check_fit(cal, args.strict, "views")
    files = []
    if args.camera_out:
        comment = f"casecal: the camera fitted with {args.robot} from {args.measurements}"
        later = {k: v for k, v in cal.camera.sessions.items() if k != meas.labels[0]}
        files.append((args.camera_out, camera_text(cal.camera.setup, comment, later)))
    _write_outputs(args, cal, files)
    if args.camera_out:
        print(f"fitted camera, board and lens written to {args.camera_out}")
    if held is not None:
        print(f"\nValidation on {held.n_poses} held-out views (--holdout {args.holdout}):")
        print(validate(cal.robot, held, robot, camera=cal.camera.setup))


def _how_to_load(path, robot) -> str:
    if robot.is_tree and str(path).lower().endswith(".urdf"):  # the file has every link
        return f"load it with casecal.load_robot or --tip-link {','.join(robot.tips)}"
    return "load it with casecal.load_robot"


def _write_calibrated(args: argparse.Namespace, robot) -> None:
    """Write -o's calibrated robot file, recording which nominal it came from."""
    if args.output:
        write_atomic(args.output, _robot_text(args, robot))
        print(f"\ncalibrated robot written to {args.output} ({_how_to_load(args.output, robot)})")


def _check_robot_format(args: argparse.Namespace, robot) -> None:
    """Refuse, before the fit, an -o format that cannot hold this robot (a UR kinematics
    file for a robot without UR joints): the calibrated one would not fit either."""
    if args.output:
        from .model.save import robot_text

        robot_text(robot, args.output)


def _robot_text(args: argparse.Namespace, robot) -> str:
    """The -o file's text in the format its extension names (.toml, .urdf); what that
    format cannot hold is said on standard error."""
    from .model.save import export

    origin = args.robot
    if is_path(origin) and Path(origin).is_file():  # relative to the output's folder, as
        # loading reads it; './arm', never 'arm' (a catalog name)
        origin = path_text(
            os.path.relpath(Path(origin).resolve(), Path(args.output).resolve().parent)
        )
    out = export(dataclasses.replace(robot, calibrated_from=origin, auto_beta=False), args.output)
    for note in out.notes:  # the file read back and checked: what it loses is a warning
        kind = "casecal: warning" if note == out.statement else "note"
        print(f"{kind}: {args.output}: {note}", file=sys.stderr)
    return out.text


def _write_outputs(args: argparse.Namespace, cal, files=()) -> None:
    """-o and --deviations-out (and `files`, (path, text) pairs) together: all written to
    temporary files first, then renamed, the robot file last (it is the calibration; the
    others describe it)."""
    files = list(files)
    if args.deviations_out:
        files.append((args.deviations_out, _deviations_text(cal, args.deviations_out)))
    if args.output:
        files.append((args.output, _robot_text(args, cal.robot)))
    write_together(files)  # each file recorded as its rename is done, for Ctrl-C's line
    if args.output:
        print(
            f"\ncalibrated robot written to {args.output} ({_how_to_load(args.output, cal.robot)})"
        )
    if args.deviations_out:
        print(f"deviations with standard errors written to {args.deviations_out}")


def _deviations_text(cal, path: str) -> str:
    if path.endswith(".json"):
        import json

        def number(v: float) -> float | None:  # JSON has no NaN: a held parameter's is null
            return v if np.isfinite(v) else None

        data = {
            n: {
                "deviation": number(cal.deviations[n]),
                "standard_error": number(cal.standard_errors[n]),
                "unit": unit(n),
                "estimated": n in cal.estimated,
            }
            for n in cal.parameters
        }
        return json.dumps(
            {"robot": cal.nominal.name, "method": cal.method, "rms_m": cal.rms, "parameters": data},
            indent=2,
            allow_nan=False,
        )
    table = cal.table.copy()
    table.insert(3, "deviation_si", [cal.deviations[n] for n in cal.parameters])
    table.insert(4, "std_error_si", [cal.standard_errors[n] for n in cal.parameters])
    table.insert(5, "si_unit", [unit(n) for n in cal.parameters])
    return table.to_csv(index=False, float_format="%.12g", lineterminator="\n")


def _cmd_calibrate_until(args: argparse.Namespace) -> None:
    from .design.campaign import calibrate_until, pool_measure

    robot = _with_sizes(robot_for(args, args.robot), args)
    pool = read_csv(args.pool, robot)
    if args.output:
        _check_writable_dir(os.path.dirname(os.path.abspath(args.output)))
        _check_robot_format(args, robot)
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
    print(run)
    print()
    print(run.calibration.summary())
    if not run.reached:
        raise CalibrationError(
            f"the pool's poses did not reach {args.threshold} (predicted "
            f"{run.predicted * 1e3:.3f} mm); nothing written"
        )
    cal = _without_poorly_determined(run.calibration, run.measurements, {}, strict=False)
    _write_calibrated(args, cal.robot)


def _cmd_validate(args: argparse.Namespace) -> None:
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
    print(validate(calibrated, meas, nominal))


def _cmd_report(args: argparse.Namespace) -> None:
    from .report import build_report  # a leaf: matplotlib only when a report is asked for

    executor = "dask" if args.scheduler else args.executor
    build_report(  # checks its folder before any study, and makes it only when it is done
        args.output,
        quick=args.quick,
        executor=executor,
        workers=args.workers,
        scheduler=args.scheduler,
        log=lambda m: print(m, flush=True),
    )


def _check_writable_dir(path) -> None:
    from pathlib import Path

    p = Path(path)
    if p.exists() and not p.is_dir():
        raise CalibrationError(f"{str(p)!r} is a file, not a folder; choose another output")
    if not p.exists() and not p.absolute().parent.is_dir():
        # one new folder is what was asked for; more is a mistyped path
        raise CalibrationError(
            f"cannot create output folder {str(p)!r}: {str(p.absolute().parent)!r} does not "
            "exist either (check the path, or create the folders first)"
        )
    try:
        p.mkdir(exist_ok=True)
    except OSError as exc:
        raise CalibrationError(f"cannot create output folder {str(p)!r}: {exc.strerror}") from None
    if not os.access(p, os.W_OK):
        raise CalibrationError(f"output folder {str(p)!r} is not writable; choose another with -o")


def _cmd_observability(args: argparse.Namespace) -> None:
    robot = robot_for(args, args.robot)
    q = _schedule(robot, args)
    obs = observability(robot, q, args.parameters)
    print(f"{robot.name}, {args.schedule} schedule, {args.poses} poses")
    print(obs)


def _cmd_robots(args: argparse.Namespace) -> None:
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


def robot_for(args: argparse.Namespace, name: str):
    """`load_robot(name)`, with --base-link and --tip-link for a URDF file (several tip
    links, comma-separated: a kinematic tree)."""
    note = namesake_note(name)  # a catalog name wins over a file named alike: say so
    if note:
        print(f"casecal: note: {note}", file=sys.stderr)
    if str(name).lower().endswith((".urdf", ".xacro")):
        ends = {k: getattr(args, k, None) for k in ("base_link", "tip_link")}
        tips = ends["tip_link"]
        if tips is not None and "," in tips:
            ends["tip_link"] = [t.strip() for t in tips.split(",")]
            if not all(ends["tip_link"]):
                raise CalibrationError(
                    f"--tip-link {tips!r}: give link names separated by commas, e.g. "
                    "--tip-link right_marker,left_marker"
                )
        return load_robot(name, **ends)
    return load_robot(name)


def _fmt(value: float, width: int = 10) -> str:
    return f"{value:{width}.4f}"


def _cmd_show(args: argparse.Namespace) -> None:
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


def _one_line_warning(message, category, filename, lineno, file=None, line=None):
    print(f"casecal: warning: {message}", file=sys.stderr)


class _Parser(argparse.ArgumentParser):
    """argparse with the project's error convention: one line on stderr, exit code 2."""

    def error(self, message: str):
        sys.stderr.write(f"casecal: error: {message} (see '{self.prog} --help')\n")
        sys.exit(2)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``casecal`` command."""
    parser = _Parser(
        prog="casecal",
        description="Kinematic calibration of serial robot arms: robot models with exact "
        "parameter Jacobians (CasADi), identification of DH errors from measured positions.",
        epilog="Robots are catalog names (see 'casecal robots') or paths to robot TOML files. "
        "Lengths print in mm, angles in degrees.",
    )
    parser.add_argument("--version", action="version", version=f"casecal {__version__}")
    parser.add_argument(
        "-v",
        "--verbose",
        action="count",
        default=0,
        help="log what the library does (-vv for debug detail)",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    # -v also after the command (casecal validate ... -v); SUPPRESS keeps the top level's
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument(
        "-v", "--verbose", action="count", default=argparse.SUPPRESS, help=argparse.SUPPRESS
    )
    # only commands that load robots get the URDF chain's ends (report would ignore them)
    urdf_ends = argparse.ArgumentParser(add_help=False)
    for end in ("base", "tip"):
        urdf_ends.add_argument(
            f"--{end}-link",
            metavar="LINK",
            default=argparse.SUPPRESS,
            help=f"URDF robots: the chain's {end} link (default: "
            + (
                "the root)"
                if end == "base"
                else "the end of the one movable chain; several, comma-separated: a "
                "kinematic tree measured at each, CSV columns LINK_x_mm …)"
            ),
        )

    def command(name, urdf=True, **kwargs):
        return sub.add_parser(name, parents=[common, urdf_ends] if urdf else [common], **kwargs)

    p = command(
        "robots",
        urdf=False,
        help="list the robot catalog (name, dof, joint types, source)",
        description="List the robots in casecal's catalog.",
    )
    p.add_argument("--wide", action="store_true", help="do not shorten the source column")
    p.set_defaults(func=_cmd_robots)

    p = command(
        "show",
        help="print a robot's DH table in mm and degrees",
        description="Print the DH table (theta, d, a, alpha, Hayati beta, joint limits) of a "
        "catalog robot or a robot TOML file, in mm and degrees, with its source.",
    )
    p.add_argument(
        "robot", metavar="NAME|FILE", help="catalog name (e.g. scorbot), .toml or .urdf path"
    )
    p.set_defaults(func=_cmd_show)

    def add_schedule(p, default_poses):
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

    def add_sizes(p):
        for flag, what, ratio, default in (
            ("--plausible-length-mm", "lengths, mm", "0.4", "2.5"),
            ("--plausible-angle-deg", "angles, degrees", "0.2", "0.5"),
        ):
            p.add_argument(
                flag,
                type=cli_args.size,
                default=None,
                metavar="SIZE",
                help=f"the largest deviation expected of the robot's {what}: a parameter "
                "whose standard error exceeds it (while it moves the points by less than the "
                f"noise) is held, and an estimate whose standard error exceeds {ratio} of it "
                "is poorly determined (not written) (default: the robot file's [plausible], "
                f"else {default})",
            )

    robot_out_help = (
        "write the calibrated robot here: .toml, .urdf (a URDF robot's own file with the "
        "calibrated numbers; a DH robot as a new URDF) or .yaml (UR kinematics file)"
    )
    params_help = (
        "parameters: names, families or 'all', comma-separated, e.g. "
        "'theta*,a*,d*' or '*.offset' (default: the paper's theta, a, d, a URDF robot's "
        "joint origins, and any error terms; 'a*' never means alpha)"
    )
    p = command(
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
    p.set_defaults(func=_cmd_simulate)

    p = command(
        "identify",
        help="identify parameter deviations from a measurement CSV",
        description="Identify the parameter deviations of ROBOT from measured positions, print "
        "a summary (mm, degrees) with standard errors and what the data cannot see, and "
        "optionally write the calibrated robot as TOML.",
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
    p.add_argument(
        "--method",
        choices=METHODS,
        default=DEFAULT_METHOD,
        help="gauss-newton, lm: iterated least squares; ipopt: CasADi NLP; svd: the "
        f"paper's one-shot linearised step (default {DEFAULT_METHOD})",
    )
    p.add_argument("--parameters", default=None, help=params_help)
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
    p.add_argument(
        "--deviations-out",
        metavar="FILE",
        help="write deviations and standard errors as .json or .csv",
    )
    p.add_argument(
        "--pairs",
        metavar="CSV",
        help="relative measurements: CSV of i, j, distance_mm (0-based rows of the measurement "
        "file, whose positions are then not needed)",
    )
    p.add_argument(
        "--camera",
        metavar="TOML",
        help="camera calibration: the measurement file has c{k}_u_px, c{k}_v_px columns of a "
        "checkerboard's corners per view, and this file the nominal camera, board and lens "
        "(a [camera] table: mode, camera_xyz_mm, camera_rpy_deg, target_xyz_mm, "
        "target_rpy_deg, fx, fy, cx, cy, distortion, image_size, board_rows, board_cols, "
        "board_spacing_mm)",
    )
    p.add_argument(
        "--sigma-px",
        metavar="PX",
        type=float,
        help="with --camera: the pixel noise sigma, px (when the file has no sigma_px column)",
    )
    p.add_argument(
        "--camera-out",
        metavar="TOML",
        help="with --camera: write the fitted camera, board pose and lens here",
    )
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
    p.add_argument("-o", "--output", metavar="FILE", help=robot_out_help)
    p.set_defaults(func=_cmd_identify)

    p = command(
        "observability",
        help="what a pose set can identify, and what it cannot",
        description="Rank, identifiable and unidentifiable parameters, blind combinations in "
        "words, and observability indices O1-O5 of a pose schedule.",
    )
    p.add_argument("robot", metavar="ROBOT", help="catalog name, .toml or .urdf path")
    add_schedule(p, 100)
    p.add_argument("--parameters", default=None, help=params_help)
    p.set_defaults(func=_cmd_observability)

    p = command(
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
    p.add_argument("--parameters", default=None, help=params_help)
    add_sizes(p)
    p.add_argument("-o", "--output", metavar="FILE", help=robot_out_help)
    p.set_defaults(func=_cmd_calibrate_until)

    p = command(
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
    p.set_defaults(func=_cmd_validate)

    from . import cli_compare, cli_compensate

    cli_compensate.add_command(command)
    cli_compare.add_command(command)

    p = command(
        "report",
        urdf=False,
        help="run every study and write the PDF report, figures and tables",
        description="Run the eleven studies (the paper's Table 1; planar arms; SCARA "
        "observability; pose count; noise; six-axis arms with Hayati's beta; optimal poses; "
        "calibrate until a target; relative measurements; compliance under gravity; an "
        "elastic humanoid tree) and write "
        "casecal-report.pdf with every figure as PNG and every table as CSV into the "
        "output folder. About 4.5 minutes on 2 idle cores (--quick: about 105 s); the first "
        "run on a machine also compiles its kernels, minutes more.",
    )
    p.add_argument(
        "-o",
        "--output",
        default="reports",
        metavar="DIR",
        help="output folder (default reports/). Only files an earlier report wrote there "
        "(listed in its hidden .casecal-report) are replaced; every other file is kept, and "
        "a file of yours with a name the report writes stops the report instead of being "
        "overwritten",
    )
    p.add_argument("--quick", action="store_true", help="smaller grids: fewer poses and trials")
    p.add_argument(
        "--executor",
        choices=("processes", "serial"),
        default="processes",
        help="run trials in local processes (default) or in this process",
    )
    p.add_argument(
        "--workers",
        type=cli_args.workers,
        default=None,
        help="local processes, at most four per core (default: one per core)",
    )
    p.add_argument(
        "--scheduler",
        type=cli_args.scheduler,
        metavar="ADDRESS",
        help="run trials on a dask cluster, e.g. tcp://host:8786 "
        "(needs: pip install 'casecal[distributed]')",
    )
    p.set_defaults(func=_cmd_report)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the ``casecal`` command; returns the exit code.

    0 success; 2 a user error, one line on stderr; 130 interrupted (Ctrl-C) and 143
    terminated (SIGTERM), one line saying what was written; 1 a bug, with its traceback.
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    level = {0: logging.WARNING, 1: logging.INFO}.get(args.verbose, logging.DEBUG)
    logging.basicConfig(level=level, format="casecal: %(levelname)s: %(message)s")
    warnings.showwarning = _one_line_warning
    with recording() as written, sigterm_unwinds():  # written: as each file is in place
        try:
            cli_args.check_outputs(args)
            args.func(args)
        except CalibrationError as exc:
            print(f"casecal: error: {exc}", file=sys.stderr)
            return 2
        except KeyboardInterrupt as exc:
            done = f"written: {', '.join(written)}" if written else "nothing was written"
            how = "terminated" if isinstance(exc, Terminated) else "interrupted"
            print(f"casecal: {how}; {done}", file=sys.stderr)
            return 143 if isinstance(exc, Terminated) else 130
        except BrokenPipeError:  # e.g. `casecal robots | head`
            return 0
        except OSError as exc:  # the system refused a read or write the library did not foresee
            where = f" {exc.filename!r}" if exc.filename else ""
            print(f"casecal: error:{where} {exc.strerror or exc}", file=sys.stderr)
            return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
