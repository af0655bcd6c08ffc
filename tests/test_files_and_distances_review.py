"""Defects an adversarial review found in the camera files, the camera command line and
the distance fit, each as the minimal case that showed it (all fixed; each fails without
its fix): a board spacing in another unit scaling the arm with success, --camera-out over
an input or another output, corners outside the image, text where numbers belong, URDF
angles shown in mm, a mix of zero and stated distance σ."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from test_camera_fit import scenario

import casecal as cc
from casecal.cli import main
from casecal.errors import CalibrationError
from casecal.observations.files import camera_text, read_camera, read_pixels, write_pixels


@pytest.fixture(scope="module")
def puma():
    return cc.load_robot("puma560")


def _files(tmp_path, puma, views=60, **changes):
    """views.csv and camera.toml of the eye-to-hand scenario, the camera file with
    `changes` (key -> TOML value text) written over the nominal's."""
    true_robot, _, nominal, meas = scenario(puma, "eye_to_hand", views=views)
    write_pixels(tmp_path / "views.csv", meas, puma)
    lines = camera_text(nominal).splitlines()
    for key, value in changes.items():
        lines = [f"{key} = {value}" if line.startswith(f"{key} =") else line for line in lines]
    (tmp_path / "camera.toml").write_text("\n".join(lines) + "\n")
    return true_robot


@pytest.mark.parametrize("spacing_mm", ["0.02", "2"])
def test_board_spacing_given_in_m_where_mm_is_asked_is_not_a_success(tmp_path, puma, spacing_mm):
    """board_spacing_mm = 0.02 (the metres of a 20 mm square): a 0.02 mm square. The fit
    scales the whole arm down 1000× to match and says success (a2 of the PUMA 560: 0.43 m
    fitted as 0.5 mm); every held-out pixel is predicted to the noise, so only the door or
    a look at the arm's size can catch it. Expected: refused (a square under ~1 mm is no
    printed board: "m for mm?") or at least success False naming the spacing. The same
    with 2 (cm for mm): every length of the arm fitted 10x short, success True; the arm's
    nominal lengths are known to far better than 50 %, so a fit that rescales them all
    is a unit slip, not a calibration."""
    _files(tmp_path, puma, board_spacing_mm=spacing_mm)
    try:
        setup = read_camera(tmp_path / "camera.toml")
        meas = read_pixels(tmp_path / "views.csv", puma, setup)
        cal = cc.identify(puma, meas, "all")
    except CalibrationError:
        return
    ratio = cal.robot.parameters["a2"] / puma.parameters["a2"]
    assert not cal.success, f"success with every length scaled by {ratio:.3g}"


def test_camera_out_does_not_replace_the_measurement_file(tmp_path, puma, capsys):
    """--camera-out VIEWS.csv (the input) replaced the user's measurements with a TOML;
    -o of an input is refused before any work (cli_args.check_outputs), --camera-out not
    (it is missing from cli_args.OUTPUTS)."""
    _files(tmp_path, puma, views=8)
    views = tmp_path / "views.csv"
    before = views.read_text()
    argv = ["identify", "puma560", str(views), "--camera", str(tmp_path / "camera.toml")]
    assert main([*argv, "--parameters", "all", "--camera-out", str(views)]) == 2
    assert "replace that input" in capsys.readouterr().err
    assert views.read_text() == before


def test_camera_out_and_o_naming_one_file_is_refused(tmp_path, puma, capsys):
    """-o X.toml --camera-out X.toml: both 'written', the robot replaces the camera."""
    _files(tmp_path, puma, views=8)
    same = str(tmp_path / "same.toml")
    argv = ["identify", "puma560", str(tmp_path / "views.csv")]
    argv += ["--camera", str(tmp_path / "camera.toml"), "--parameters", "all"]
    assert main([*argv, "-o", same, "--camera-out", same]) == 2
    assert "both name" in capsys.readouterr().err


def test_a_camera_file_whose_camera_is_not_a_table_is_refused(tmp_path):
    """``camera = 3``: a TypeError from read_camera, not a CalibrationError."""
    path = tmp_path / "camera.toml"
    path.write_text("camera = 3\n")
    with pytest.raises(CalibrationError, match=r"\[camera\]"):
        read_camera(path)


def test_corners_outside_the_image_size_are_refused(tmp_path, puma):
    """image_size = [640, 480] for a 1280 × 1024 camera's corners: read and fitted without
    a word, and the fitted camera file then carries the wrong size (simulate_pixels with
    it refuses every view). Expected: read_pixels (or PixelMeasurements) refuses corners
    outside the image, naming image_size."""
    _files(tmp_path, puma, views=8, image_size="[640, 480]")
    setup = read_camera(tmp_path / "camera.toml")
    with pytest.raises(CalibrationError, match="image"):
        read_pixels(tmp_path / "views.csv", puma, setup)


def test_mirror_message_gives_urdf_angles_in_mrad(tmp_path):
    """A URDF robot's roll/pitch/yaw/offset are angles; the mirror check's message printed
    them in mm ("joint6.roll = +0 mm or +1 mm"): mirror._values decides by DH name prefixes
    instead of casecal.model.parameters.unit."""
    from casecal.identification.mirror import _values

    path = tmp_path / "ur5e.urdf"
    cc.save_robot(cc.load_robot("ur5e"), path)
    arm = cc.load_robot(path)
    roll = next(n for n in arm.parameter_names if n.endswith(".roll"))
    a, b = arm.with_deviations({roll: 1e-3}), arm.with_deviations({roll: -1e-3})
    text = _values(arm, a, b, [roll], cc.poses.uniform(arm, 10, seed=0))
    assert "mrad" in text and " mm" not in text, text


def test_camera_files_hold_fx_as_a_number(tmp_path, puma):
    """fx = "1400" (a TOML string) is taken without a word; every other number of the
    file is refused as text ("must be 3 numbers", "board_rows = '7'")."""
    _files(tmp_path, puma, views=4, fx='"1400"')
    with pytest.raises(CalibrationError, match="fx"):
        read_camera(tmp_path / "camera.toml")


def test_zero_padded_corner_columns_are_refused_not_a_traceback(tmp_path, puma):
    """c00_u_px (a detector script's "c{k:02d}"): the column pattern reads it as corner 0,
    then the reader looks up 'c0_u_px' by name: KeyError, a traceback (exit 1)."""
    _files(tmp_path, puma, views=4)
    views = tmp_path / "views.csv"
    views.write_text(views.read_text().replace("c0_u_px", "c00_u_px", 1))
    setup = read_camera(tmp_path / "camera.toml")
    with pytest.raises(CalibrationError, match="c00_u_px"):
        read_pixels(views, puma, setup)


def test_camera_out_is_a_toml_file(tmp_path, puma, capsys):
    _files(tmp_path, puma, views=8)
    argv = ["identify", "puma560", str(tmp_path / "views.csv")]
    argv += ["--camera", str(tmp_path / "camera.toml"), "--camera-out", str(tmp_path / "c.urdf")]
    assert main(argv) == 2
    assert "name it .toml" in capsys.readouterr().err


def test_a_mix_of_zero_and_stated_distance_sigmas_is_refused():
    from casecal.identification.distances import (
        identify_distances,
        random_pairs,
        simulate_distances,
    )

    arm = cc.load_robot("rrr")
    meas = simulate_distances(arm, cc.poses.uniform(arm, 30, seed=0), random_pairs(30, 60))
    mixed = dataclasses.replace(meas, sigma=np.r_[0.0, np.full(59, 1e-5)])
    with pytest.raises(CalibrationError, match="zero for some pairs"):
        identify_distances(arm, mixed)


def test_a_planar_arm_fitted_from_distances_without_its_tilts_says_so():
    """The paper's default set leaves a planar arm's tilts (α, β) out; distances see them
    at second order only, so the fit takes the arm to be flat. A true arm tilted by about
    1 mrad is then 1.1 mm off on new poses with nothing in the residuals: the summary must
    say what the fit assumed and what to do."""
    from casecal.identification.distances import (
        identify_distances,
        random_pairs,
        simulate_distances,
    )

    arm = cc.load_robot("rrr")
    rng = np.random.default_rng(0)
    names = [n for n in arm.parameter_names if not n.startswith("base_")]
    true = arm.with_deviations({n: rng.normal(0, 1e-3) for n in names})
    q = cc.poses.uniform(arm, 60, seed=0)
    meas = simulate_distances(true, q, random_pairs(60, 400, seed=0), noise=1e-5, seed=0)
    cal = identify_distances(arm, meas)
    assert "takes the arm to be flat" in str(cal.summary())
    assert "alpha1" in cal.start_note
    spatial = cc.load_robot("kr15_2")
    q = cc.poses.uniform(spatial, 30, seed=0)
    meas = simulate_distances(spatial, q, random_pairs(30, 200, seed=0), noise=1e-5, seed=0)
    assert identify_distances(spatial, meas).start_note == ""
