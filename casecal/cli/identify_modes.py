"""``casecal identify --pairs`` and ``--camera``: fits of distances and of a camera's
pixels, beside identify's fit of positions (`casecal.cli.identify`)."""

from __future__ import annotations

import argparse

from ..errors import CalibrationError
from ..identification.fit import identify
from ..identification.validation import split, validate
from .common import say
from .writing import check_fit, check_robot_format, write_calibrated, write_outputs


def add_modes(p: argparse.ArgumentParser) -> None:
    """identify's --pairs, --camera, --sigma-px and --camera-out."""
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


def identify_distances(args: argparse.Namespace, robot) -> None:
    """identify --pairs: the measurement file's rows are joined by measured distances."""
    from ..identification import distances

    meas = distances.read_distance_csv(args.measurements, args.pairs, robot)
    method = "gauss-newton" if args.method == "ipopt" else args.method
    cal = distances.identify_distances(
        robot, meas, args.parameters, method, max_iterations=args.max_iterations
    )
    say(f"{meas.n_pairs} distances between {len(meas.q)} poses")
    say(cal.summary())
    if not cal.success:
        raise CalibrationError(f"the fit did not pass ({cal.message}); nothing written")
    write_calibrated(args, cal.robot)


def identify_camera(args: argparse.Namespace, robot) -> None:
    """identify --camera: the measurement file is a camera's (`casecal.observations.files`)."""
    from ..observations.files import camera_text, read_cameras, read_pixels

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
    check_robot_format(args, robot)
    sigma = None if args.sigma_px is None else float(args.sigma_px)
    setup, placements = read_cameras(args.camera)
    meas = read_pixels(args.measurements, robot, setup, sigma, sessions=placements)
    found = int(meas.found.sum())
    say(f"{meas.n_poses} views, {found} corners found of {meas.pixels.shape[1]} per view")
    held = None
    if args.holdout:
        meas, held = split(meas, args.holdout, seed=args.seed)
    cal = identify(robot, meas, args.parameters, args.method, max_iterations=args.max_iterations)
    say(cal.summary())
    say(
        f"RMS pixel error: {cal.camera.rms_px_before:.3g} px with the camera and board "
        f"poses alone fitted, {cal.camera.rms_px:.3g} px calibrated (sigma {meas.sigma_px:g} px)"
    )
    check_fit(cal, args.strict, "views")
    files = []
    if args.camera_out:
        comment = f"casecal: the camera fitted with {args.robot} from {args.measurements}"
        later = {k: v for k, v in cal.camera.sessions.items() if k != meas.labels[0]}
        files.append((args.camera_out, camera_text(cal.camera.setup, comment, later)))
    write_outputs(args, cal, files)
    if args.camera_out:
        say(f"fitted camera, board and lens written to {args.camera_out}")
    if held is not None:
        print(f"\nValidation on {held.n_poses} held-out views (--holdout {args.holdout}):")
        print(validate(cal.robot, held, robot, camera=cal.camera.setup))
