"""Camera measurement files and camera files: written, read back, refused when wrong.

The files a lab writes from its detector (one row per view: joints, each corner's u, v in
pixels) and its camera (poses, lens, board, in mm and degrees), read into what
`casecal.identify` takes; then the command line's `identify --camera` on them.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from test_camera_fit import SIGMA, scenario

import casecal as cc
from casecal.errors import CalibrationError
from casecal.observations.files import camera_text, read_camera, read_pixels, write_pixels


@pytest.fixture(scope="module")
def puma():
    return cc.load_robot("puma560")


def test_pixel_files_round_trip(tmp_path, puma):
    _, _, nominal, meas = scenario(puma, "eye_to_hand", views=12)
    uv = meas.pixels.copy()
    uv[3, :5] = np.nan  # corners not found: empty cells
    meas = dataclasses.replace(meas, pixels=uv)
    path = tmp_path / "views.csv"
    write_pixels(path, meas, puma)
    header = path.read_text().splitlines()[0].split(",")
    assert header[:7] == ["q1_deg", "q2_deg", "q3_deg", "q4_deg", "q5_deg", "q6_deg", "c0_u_px"]
    assert header[-1] == "sigma_px" and len(header) == 6 + 2 * 63 + 1
    assert ",,," in path.read_text().splitlines()[4]  # view 3's missing corners, empty
    again = read_pixels(path, puma, nominal)
    np.testing.assert_allclose(again.q, meas.q, rtol=1e-15, atol=1e-15)
    np.testing.assert_array_equal(np.isnan(again.pixels), np.isnan(meas.pixels))
    np.testing.assert_allclose(again.pixels, meas.pixels, rtol=1e-15)
    assert again.sigma_px == SIGMA


def test_camera_files_round_trip(tmp_path, puma):
    _, truth, _, _ = scenario(puma, "eye_in_hand", views=5)
    path = tmp_path / "camera.toml"
    path.write_text(camera_text(truth, comment="a test camera"))
    again = read_camera(path)
    assert again.mode == truth.mode and again.board == truth.board
    assert again.intrinsics == truth.intrinsics and again.image_size == truth.image_size
    np.testing.assert_allclose(again.camera, truth.camera, atol=1e-12)
    np.testing.assert_allclose(again.target, truth.target, atol=1e-12)


def test_wrong_files_are_refused_with_what_to_fix(tmp_path, puma):
    _, truth, nominal, meas = scenario(puma, "eye_to_hand", views=5)
    path = tmp_path / "views.csv"
    write_pixels(path, meas, puma)
    small = dataclasses.replace(nominal, board=cc.Checkerboard(rows=6, cols=9))
    with pytest.raises(CalibrationError, match=r"columns up to c62.*6 × 9 = 54"):
        read_pixels(path, puma, small)
    text = path.read_text().splitlines()
    cells = text[2].split(",")
    cells[7] = ""  # v of corner 0 empty, u not
    path.write_text("\n".join([text[0], text[1], ",".join(cells), *text[3:]]) + "\n")
    with pytest.raises(CalibrationError, match="one coordinate missing"):
        read_pixels(path, puma, nominal)
    cells[7] = "abc"
    path.write_text("\n".join([text[0], text[1], ",".join(cells), *text[3:]]) + "\n")
    with pytest.raises(CalibrationError, match=r"row 3, column 'c0_v_px': 'abc'"):
        read_pixels(path, puma, nominal)
    text[0] = "session," + text[0]
    rows = [f"{'AB'[k % 2]},{line}" for k, line in enumerate(text[1:])]
    path.write_text("\n".join([text[0], *rows]) + "\n")
    with pytest.raises(CalibrationError, match=r"sessions A, B in the views, placements none"):
        read_pixels(path, puma, nominal)
    camera = tmp_path / "camera.toml"
    camera.write_text(camera_text(truth).replace("fx = ", "f_x = "))
    with pytest.raises(CalibrationError, match=r"missing fx.*fx \(focal length along u, px\)"):
        read_camera(camera)
    camera.write_text(
        camera_text(truth).replace("board_spacing_mm = 20", "board_spacing_mm = 0.02")
    )
    with pytest.raises(CalibrationError, match=r"camera.toml: \[camera\] Checkerboard.*m for mm"):
        read_camera(camera)  # the metres of a 20 mm square, written as mm


def test_the_command_line_calibrates_from_camera_files(tmp_path, puma, capsys):
    """`casecal identify puma560 views.csv --camera camera.toml`: the summary, the pixel
    errors, the calibrated robot and the fitted camera written; the camera written reads
    back to the fit's."""
    from casecal.cli import main

    _, _, nominal, meas = scenario(puma, "eye_to_hand", views=60)
    views, camera = tmp_path / "views.csv", tmp_path / "camera.toml"
    write_pixels(views, meas, puma)
    camera.write_text(camera_text(nominal))
    robot_out, camera_out = tmp_path / "puma.toml", tmp_path / "fitted.toml"
    argv = ["identify", "puma560", str(views), "--camera", str(camera), "--parameters", "all"]
    code = main([*argv, "-o", str(robot_out), "--camera-out", str(camera_out)])
    out = capsys.readouterr().out
    assert code == 0, out
    assert "60 views, 3780 corners found of 63 per view" in out
    assert "Camera calibration, eye-to-hand" in out and "RMS pixel error:" in out
    calibrated = cc.load_robot(str(robot_out))
    fitted = read_camera(camera_out)
    cal = cc.identify(puma, read_pixels(views, puma, nominal), "all")
    np.testing.assert_allclose(calibrated.vector(), cal.robot.vector(), atol=1e-12)
    np.testing.assert_allclose(fitted.camera, cal.camera.setup.camera, atol=1e-12)
    assert fitted.intrinsics.fx == pytest.approx(cal.camera.setup.intrinsics.fx, abs=1e-9)
    # a fifth of the views held out: the calibrated model at the noise floor on them
    assert main([*argv, "--holdout", "0.2"]) == 0
    out = capsys.readouterr().out
    assert "Validation on 12 held-out views (--holdout 0.2):" in out
    after = next(line for line in out.splitlines() if line.startswith("after"))
    assert float(after.split()[1]) < 1.15 * np.sqrt(2) * SIGMA  # px RMS
    # options a camera fit cannot honour, refused before any work
    assert main([*argv, "--loss", "huber"]) == 2
    assert "--loss cannot be used with --camera" in capsys.readouterr().err
    assert main(["identify", "puma560", str(views), "--sigma-px", "0.3"]) == 2
    assert "--sigma-px needs --camera" in capsys.readouterr().err


def test_placements_from_files_and_the_command_line(tmp_path, puma, capsys):
    """Two placements of the camera: the views file's session column, the camera file's
    [camera.sessions.B] table; written, read back, fitted from the shell, and the fitted
    camera file read back with both placements."""
    from test_camera import PUMA_Q0

    from casecal.cli import main
    from casecal.observations.files import read_cameras
    from casecal.observations.pixels import PixelMeasurements
    from casecal.observations.simulate import select_views, simulate_pixels

    true_robot, truth, nominal, meas = scenario(puma, "eye_to_hand", views=30)
    shift = np.eye(4)
    shift[:3, 3] = [0.05, -0.03, 0.02]  # a second placement, 6 cm away

    def placed(setup):
        return dataclasses.replace(setup, camera=shift @ setup.camera)

    moved = placed(nominal)
    q2 = select_views(puma, 30, moved, seed=5, q_centre=PUMA_Q0, spread=0.3, max_tilt=0.9)
    uv2 = simulate_pixels(true_robot, q2, placed(truth), sigma_px=SIGMA, seed=6)
    labels = np.array(["A"] * 30 + ["B"] * 30)
    both = PixelMeasurements(
        np.vstack([meas.q, q2]), np.vstack([meas.pixels, uv2]), nominal, SIGMA, True, labels,
        {"B": moved},
    )  # fmt: skip
    views, camera = tmp_path / "views.csv", tmp_path / "camera.toml"
    write_pixels(views, both, puma)
    camera.write_text(camera_text(nominal, sessions={"B": moved}))
    setup, placements = read_cameras(camera)
    again = read_pixels(views, puma, setup, sessions=placements)
    assert again.labels == ("A", "B")
    np.testing.assert_allclose(again.setups["B"].camera, moved.camera, atol=1e-12)
    out = tmp_path / "fitted.toml"
    argv = ["identify", "puma560", str(views), "--camera", str(camera), "--parameters", "all"]
    assert main([*argv, "--camera-out", str(out)]) == 0, capsys.readouterr().out
    fitted, later = read_cameras(out)
    assert list(later) == ["B"]
    cal = cc.identify(puma, again, "all")
    np.testing.assert_allclose(later["B"].camera, cal.camera.sessions["B"].camera, atol=1e-12)
    np.testing.assert_allclose(fitted.camera, cal.camera.setup.camera, atol=1e-12)
