"""Camera calibration through `casecal.identify`: pixels as residual rows of the one fit.

A simulated PUMA 560 with mm-level errors, a 7 × 9 checkerboard, σ = 0.3 px, 60 views,
eye-in-hand and eye-to-hand, fitted from a nominal camera, board and lens that are off by
millimetres, degrees and pixels. Checked against what nobody here computed: the truth of
the simulation (every estimate, or the combination it stands for, within its standard
errors), held-out views (their pixel error at the noise floor), and OpenCV's
``projectPoints`` of the fitted camera (the residuals the fit reports).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from test_camera import PUMA_Q0, eye_in_hand_setup, eye_to_hand_setup

import casecal as cc
from casecal.errors import CalibrationError
from casecal.observations.pixels import PixelMeasurements, simulate_camera
from casecal.observations.residuals import moved_setup
from casecal.observations.rig import INTRINSIC_PARAMETERS, rig_robot
from casecal.observations.simulate import select_views, simulate_pixels

cv2 = pytest.importorskip("cv2")

SIGMA = 0.3  # px
SETUPS = {"eye_in_hand": eye_in_hand_setup, "eye_to_hand": eye_to_hand_setup}
OFF = {  # the true camera's offsets from the nominal one
    "camera_x": 3e-3,
    "camera_wz": 5e-3,
    "target_y": -2e-3,
    "target_wx": 4e-3,
    "fx": 12.0,
    "fy": 8.0,
    "cx": -4.0,
    "k1": 0.01,
}


@pytest.fixture(scope="module")
def puma():
    return cc.load_robot("puma560")


def scenario(puma, mode, seed=3, views=60):
    """(true robot, true setup, nominal setup, measurements from the nominal)."""
    nominal = SETUPS[mode](puma)
    rng = np.random.default_rng(seed)
    dh = [n for n in puma.parameter_names if not n.startswith(("base_", "tool_"))]
    true_robot = puma.with_deviations({n: rng.normal(0, 1e-3) for n in dh})
    true_setup = moved_setup(nominal, OFF)
    q = select_views(puma, views, nominal, seed=1, q_centre=PUMA_Q0, spread=0.3, max_tilt=0.9)
    meas = simulate_camera(true_robot, q, true_setup, SIGMA, seed=seed + 1)
    return true_robot, true_setup, nominal, dataclasses.replace(meas, setup=nominal)


@pytest.fixture(scope="module", params=sorted(SETUPS))
def fitted(request, puma):
    true_robot, true_setup, nominal, meas = scenario(puma, request.param)
    truth_rig = rig_robot(true_robot, true_setup)
    cal = cc.identify(puma, meas, "all")
    truth = truth_rig.deviations_from(rig_robot(puma, nominal), cal.parameters)
    return cal.compare_to(truth), true_robot, true_setup, nominal, meas


def test_a_camera_calibration_recovers_the_truth_within_its_standard_errors(fitted):
    cal, *_ = fitted
    assert cal.success, cal.message
    assert cal.measured == "pixels"
    assert 0.9 < cal.reduced_chi2 < 1.1
    assert set(INTRINSIC_PARAMETERS) <= set(cal.estimated)  # a well-spread set sees the lens
    z = {n: (cal.deviations[n] - cal.true_value(n)) / cal.standard_errors[n] for n in cal.estimated}
    worst = max(z, key=lambda n: abs(z[n]))
    assert abs(z[worst]) < 4.5, (worst, z[worst])
    # and the fit moved: the truth was many standard errors from the start
    far = max(abs(cal.true_value(n)) / cal.standard_errors[n] for n in cal.estimated)
    assert far > 20


def test_held_out_views_are_at_the_noise_floor(fitted, puma):
    """The calibrated robot (its own frames) with the fitted camera predicts new views as
    well as the noise allows; the nominal robot with only the poses fitted does not."""
    cal, true_robot, true_setup, nominal, _ = fitted
    q = select_views(puma, 30, nominal, seed=11, q_centre=PUMA_Q0, spread=0.3, max_tilt=0.9)
    seen = simulate_pixels(true_robot, q, true_setup, sigma_px=SIGMA, seed=12)
    after = np.sqrt(np.mean((seen - simulate_pixels(cal.robot, q, cal.camera.setup)) ** 2))
    before = np.sqrt(np.mean((seen - simulate_pixels(puma, q, cal.camera.setup_before)) ** 2))
    assert after < 1.1 * SIGMA
    assert before > 1.5 * SIGMA
    assert cal.robot.name == puma.name and cal.robot.base == puma.base  # the user's frames


def test_reported_pixel_residuals_are_opencvs(fitted):
    """The residuals the fit reports are the measured pixels minus ``cv2.projectPoints`` of
    the fitted camera and board through the calibrated robot."""
    cal, *_, meas = fitted
    setup = cal.camera.setup
    K, dist = setup.intrinsics.to_opencv()
    for i in (0, 17, 59):
        T = cal.robot.fk(meas.q[i])
        if setup.mode == "eye_in_hand":
            M = np.linalg.inv(T @ setup.camera) @ setup.target
        else:
            M = np.linalg.inv(setup.camera) @ T @ setup.target
        corners = setup.board.corners()
        uv, _ = cv2.projectPoints(corners, cv2.Rodrigues(M[:3, :3])[0], M[:3, 3], K, dist)
        expected = meas.pixels[i] - uv.reshape(-1, 2)
        np.testing.assert_allclose(cal.camera.pixel_residuals[i], expected, atol=1e-6)
    rms = np.sqrt(np.mean(cal.camera.pixel_residuals**2))
    assert rms == pytest.approx(cal.camera.rms_px)
    assert 0.9 * SIGMA < rms < 1.1 * SIGMA


def test_the_summary_says_what_the_frames_are_and_what_is_blind(fitted):
    cal, *_ = fitted
    text = str(cal.summary())
    assert "Camera calibration" in text and "camera_fx" in text
    # the camera's pose takes the first joint's offset and height: blind, said by name
    assert {"theta1", "d1"} <= set(cal.unidentifiable)
    assert "theta1" in text.split("blind", 1)[1]


def test_missing_corners_are_no_observations(puma):
    _, _, _, meas = scenario(puma, "eye_to_hand", views=40)
    uv = meas.pixels.copy()
    uv[3, :10] = np.nan  # ten corners of one view not found
    uv[7, 5] = np.nan
    full = cc.identify(puma, meas, "all")
    holed = cc.identify(puma, dataclasses.replace(meas, pixels=uv), "all")
    assert holed.success, holed.message
    assert holed.dof_residual == full.dof_residual - 2 * 11
    assert np.isnan(holed.camera.pixel_residuals[3, :10]).all()
    assert np.isfinite(holed.camera.pixel_residuals[3, 10:]).all()


def test_known_intrinsics_are_held(puma):
    _, true_setup, nominal, meas = scenario(puma, "eye_in_hand", views=40)
    lens = dataclasses.replace(nominal, intrinsics=true_setup.intrinsics)
    known = dataclasses.replace(meas, setup=lens, fit_intrinsics=False)
    cal = cc.identify(puma, known, "all")
    assert cal.success, cal.message
    assert not set(INTRINSIC_PARAMETERS) & set(cal.parameters)
    assert cal.camera.setup.intrinsics == true_setup.intrinsics


def test_a_camera_calibration_refuses_what_it_cannot_do(puma):
    _, _, nominal, meas = scenario(puma, "eye_to_hand", views=10)
    with pytest.raises(CalibrationError, match="do not take loss"):
        cc.identify(puma, meas, loss="huber")
    with pytest.raises(CalibrationError, match="do not take noise"):
        cc.identify(puma, meas, noise=1e-4)
    with pytest.raises(CalibrationError, match="joint values per view"):
        cc.identify(puma, dataclasses.replace(meas, q=meas.q[:, :5]))
    flipped = dataclasses.replace(nominal, camera=nominal.camera @ np.diag([1.0, -1.0, -1.0, 1.0]))
    with pytest.raises(CalibrationError, match="behind the camera"):
        cc.identify(puma, dataclasses.replace(meas, setup=flipped))
    with pytest.raises(CalibrationError, match="sigma_px"):
        PixelMeasurements(meas.q, meas.pixels, nominal, 0.0)
    backwards = meas.pixels.copy()
    backwards[[2, 5]] = backwards[[2, 5], ::-1]  # a 7 × 9 board read after a half turn
    with pytest.raises(CalibrationError, match=r"2 of 10 views \(first: \[2, 5\]\).*reverse order"):
        cc.identify(puma, dataclasses.replace(meas, pixels=backwards))
    half = meas.pixels.copy()
    half[0, 0, 0] = np.nan
    with pytest.raises(CalibrationError, match="one coordinate missing"):
        PixelMeasurements(meas.q, half, nominal, SIGMA)


def test_a_board_turned_about_one_axis_fails_and_says_what_it_cannot_see(puma):
    """Only joint 6 turns, the board square to the camera: the lens's scale and most of the
    robot are blind, and the fit says so rather than returning numbers."""
    true_robot, true_setup, nominal, _ = scenario(puma, "eye_to_hand")
    q = np.repeat(PUMA_Q0[None], 30, axis=0)
    q[:, 5] += np.linspace(-0.6, 0.6, 30)
    meas = dataclasses.replace(
        simulate_camera(true_robot, q, true_setup, SIGMA, seed=2), setup=nominal
    )
    cal = cc.identify(puma, meas)
    assert not cal.success
    assert "in every pose" in cal.message  # the joints that never moved, by value
    assert {"camera_fx", "camera_fy", "a2", "d4"} <= set(cal.unidentifiable)


def test_validation_on_the_next_days_views(fitted, puma):
    """Held-out views taken after the camera was bumped 1 cm and 0.5°: the poses are
    refitted, and the calibrated robot with the fitted lens reaches the noise floor
    (√2 σ per corner) where the nominal one does not."""
    cal, true_robot, true_setup, nominal, _ = fitted
    bumped = moved_setup(true_setup, {"camera_x": 0.01, "camera_wy": 0.009})
    q = select_views(true_robot, 30, bumped, seed=21, q_centre=PUMA_Q0, spread=0.3, max_tilt=0.9)
    views = simulate_camera(true_robot, q, bumped, SIGMA, seed=22)
    views = dataclasses.replace(views, setup=nominal)
    check = cc.validate(cal.robot, views, puma, camera=cal.camera.setup)
    floor = np.sqrt(2) * SIGMA
    assert check.after.rms < 1.1 * floor, str(check)
    assert check.before.rms > 1.5 * floor, str(check)
    assert "held-out views" in str(check) and check.n_views == 30


def test_two_placements_of_the_camera_in_one_fit(puma):
    """Eye-to-hand, the camera moved between two sessions to see the board from another
    part of the joint space: one fit, a camera pose per session, one lens and board mount.
    New views of each session are predicted at the noise floor with that session's fitted
    camera, and the arm's standard errors are smaller than from as many views of one
    placement (the median ratio was 0.81 when measured)."""
    from test_camera import LENS

    from casecal.observations.pixels import PixelMeasurements
    from casecal.observations.simulate import CameraSetup, look_at
    from casecal.observations.target import Checkerboard

    board, mount = Checkerboard(), np.eye(4)
    mount[2, 3] = 0.1

    def camera_at(q0):
        at = puma.fk(q0) @ mount
        centre = at[:3, :3] @ board.centre + at[:3, 3]
        return CameraSetup("eye_to_hand", look_at(centre - at[:3, 2], centre), mount, LENS, board)

    q2 = PUMA_Q0 + np.array([1.2, 0.3, -0.4, 0.5, -0.4, 0.8])
    a, b = camera_at(PUMA_Q0), camera_at(q2)
    rng = np.random.default_rng(3)
    dh = [n for n in puma.parameter_names if not n.startswith(("base_", "tool_"))]
    true = puma.with_deviations({n: rng.normal(0, 1e-3) for n in dh})
    true_a = moved_setup(a, {"camera_x": 3e-3, "camera_wz": 5e-3, "target_y": -2e-3, "fx": 12.0})
    true_b = dataclasses.replace(
        moved_setup(b, {"camera_y": -4e-3, "camera_wx": 3e-3}),
        target=true_a.target,
        intrinsics=true_a.intrinsics,
    )

    def views(setup, q0, n, seed):
        return select_views(puma, n, setup, seed=seed, q_centre=q0, spread=0.3, max_tilt=0.9)

    qa, qb = views(a, PUMA_Q0, 40, 1), views(b, q2, 40, 2)
    uv = np.vstack(
        [
            simulate_pixels(true, qa, true_a, sigma_px=SIGMA, seed=4),
            simulate_pixels(true, qb, true_b, sigma_px=SIGMA, seed=5),
        ]
    )
    labels = np.array(["A"] * 40 + ["B"] * 40)
    meas = PixelMeasurements(np.vstack([qa, qb]), uv, a, SIGMA, session=labels, setups={"B": b})
    cal = cc.identify(puma, meas, "all")
    assert cal.success, cal.message
    assert 0.9 < cal.reduced_chi2 < 1.1
    assert {"base_x@B", "base_rz@B"} <= set(cal.estimated)
    for setup, truth, q0 in (
        (cal.camera.sessions["A"], true_a, PUMA_Q0),
        (cal.camera.sessions["B"], true_b, q2),
    ):
        q = views(truth, q0, 20, 11)
        seen = simulate_pixels(true, q, truth, sigma_px=SIGMA, seed=12)
        miss = np.sqrt(np.mean((seen - simulate_pixels(cal.robot, q, setup)) ** 2))
        assert miss < 1.1 * SIGMA
    # validation across both sessions: each session's poses refitted, the lens as fitted
    check = cc.validate(cal.robot, meas.subset(slice(0, 80, 3)), puma, camera=cal.camera.setup)
    assert check.after.rms < 1.1 * np.sqrt(2) * SIGMA < check.before.rms, str(check)
    one = simulate_camera(true, np.vstack([qa, views(a, PUMA_Q0, 40, 7)]), true_a, SIGMA, seed=9)
    single = cc.identify(puma, dataclasses.replace(one, setup=a), "all")
    arm = [n for n in cal.estimated if n in single.estimated and n in dh]
    ratio = np.median([cal.standard_errors[n] / single.standard_errors[n] for n in arm])
    assert ratio < 0.95
    # a later session's setup must move only the camera: one lens, board and mount
    with pytest.raises(CalibrationError, match="only its camera pose moved"):
        other = dataclasses.replace(b, target=np.eye(4))
        PixelMeasurements(meas.q, uv, a, SIGMA, session=labels, setups={"B": other})
    with pytest.raises(CalibrationError, match="give setups= a nominal camera for each"):
        PixelMeasurements(meas.q, uv, a, SIGMA, session=labels)


def test_compensated_joints_on_the_true_robot(fitted, puma):
    """Following the answer to the robot: joint targets compensated with the calibrated
    robot and the fitted mount bring the true robot's mounted board within the error the
    fit predicts across the joint ranges; the last joint's parameters, which only the
    mount sees, are named as left nominal in the calibrated robot."""
    from test_compensate_frames import robot_frame

    from casecal.model.frames import rpy_from_matrix

    cal, true_robot, true_setup, nominal, _ = fitted
    mount = "target" if nominal.mode == "eye_to_hand" else "camera"
    centre = np.eye(4)
    centre[:3, 3] = nominal.board.centre if mount == "target" else 0.0

    def mounted(robot, setup):
        T = robot.tool.matrix() @ getattr(setup, mount) @ centre
        tool = cc.Frame(tuple(T[:3, 3]), tuple(rpy_from_matrix(T[:3, :3])))
        return dataclasses.replace(robot, tool=tool, auto_beta=False)

    real, model = mounted(true_robot, true_setup), mounted(cal.robot, cal.camera.setup)
    plan = mounted(puma, nominal)
    q = cc.poses.uniform(puma, 100, seed=5)
    target = (robot_frame(plan, real) @ plan.fk(q))[:, :3, 3]
    out = cc.compensate(model, q, nominal=plan, orientation=False)
    assert out.ok.mean() > 0.8
    miss = np.linalg.norm(real.fk(out.q[out.ok])[:, :3, 3] - target[out.ok], axis=1)
    before = np.linalg.norm(real.fk(q)[:, :3, 3] - target, axis=1)
    text = next(c.text for c in cal.audit.checks if c.name.startswith("prediction"))
    predicted = float(text.split("joint limits ")[1].split(" mm")[0]) * 1e-3
    assert np.sqrt(np.mean(miss**2)) < 1.5 * predicted < np.sqrt(np.mean(before**2)) / 3
    assert "theta6, a6, alpha6, d6 stay nominal in the calibrated robot" in cal.start_note
