"""Real-data situations: unknown instrument frame and tool offset, parameters='all'."""

from __future__ import annotations

import numpy as np
import pytest

import casecal as cc
from casecal.model.parameters import select

SIGMA = 0.02e-3  # laser tracker, per coordinate


def realistic_truth(robot: cc.Robot, seed: int) -> dict[str, float]:
    """0.5-1 mm and 0.1-0.5° on every DH parameter, a far, turned instrument frame,
    and an unknown tool offset."""
    rng = np.random.default_rng(seed)
    truth = {}
    for name in select(robot.parameter_names, ["theta*", "d*", "a*", "alpha*"]):
        sign = rng.choice([-1.0, 1.0])
        if name[0] in "ad":
            truth[name] = sign * rng.uniform(0.5e-3, 1e-3)
        else:
            truth[name] = sign * np.deg2rad(rng.uniform(0.1, 0.5))
    truth.update(
        base_x=2.1,
        base_y=-1.9,
        base_z=0.4,
        base_rx=np.deg2rad(0.4),
        base_ry=np.deg2rad(-0.3),
        base_rz=np.deg2rad(130.0),
        tool_x=0.03,
        tool_y=-0.02,
        tool_z=0.12,
    )
    return truth


@pytest.mark.parametrize("name", ["puma560", "rx90b"])
def test_far_turned_instrument_one_point_per_pose(name):
    robot = cc.load_robot(name)
    true = robot.with_deviations(realistic_truth(robot, seed=1))
    q = cc.poses.uniform(robot, 60, seed=2)
    meas = cc.simulate(true, q, noise=SIGMA, seed=3)
    cal = cc.identify(robot, meas, "all", "gauss-newton")
    assert cal.success, cal.message
    # "before" is the nominal robot with the frames nobody knew fitted, not metres of
    # instrument placement: at most the nominal robot's error placed at the true frames
    truth = realistic_truth(robot, seed=1)
    frames = {n: v for n, v in truth.items() if n.startswith(("base_", "tool_"))}
    placed = meas.positions - robot.with_deviations(frames).position(q)
    placed_rms = np.sqrt(np.mean(np.sum(placed**2, axis=1)))
    assert 0.3 * placed_rms < cal.rms_before <= placed_rms, (cal.rms_before, placed_rms)
    assert 1e-3 < cal.rms_before < 0.05
    q_hold = cc.poses.uniform(robot, 200, seed=4)
    hold = cc.simulate(true, q_hold, noise=SIGMA, seed=5)
    err = hold.positions - cal.robot.position(q_hold)
    rms = np.sqrt(np.mean(np.sum(err**2, axis=1)))
    floor = SIGMA * np.sqrt(3)  # a perfect model still sees the held-out noise
    assert rms < 1.1 * floor, (rms * 1e3, floor * 1e3)
    # what it removed, and why: tool orientation does not move a single measured point
    assert {"tool_rx", "tool_ry", "tool_rz"} <= set(cal.unidentifiable)
    zero = {s.members[0] for s in cal.observability.blind_spots if "column is zero" in s.text}
    assert {"tool_rx", "tool_ry", "tool_rz"} <= zero
    assert {"tool_rx", "tool_ry", "tool_rz"} <= set(cal.held)
    text = str(cal.summary())
    assert "rigid fit" in text and "tool_rx" in text


def holdout_rms(cal, true, robot, orientation=False):
    q_hold = cc.poses.uniform(robot, 200, seed=4)
    hold = cc.simulate(true, q_hold, noise=SIGMA, seed=5)
    model = cal.robot.measured_points(q_hold)
    err = hold.points - model
    return np.sqrt(np.mean(np.sum(err**2, axis=-1)))


def test_two_reflectors_per_pose_positions_unknown():
    robot = cc.load_robot("puma560")
    truth = realistic_truth(robot, seed=6)
    del truth["tool_x"], truth["tool_y"], truth["tool_z"]  # the reflectors carry the offset
    reflectors = [[0.04, 0.0, 0.13], [-0.03, 0.02, 0.11]]
    true = robot.with_deviations(truth).with_points(reflectors)
    q = cc.poses.uniform(robot, 60, seed=2)
    meas = cc.simulate(true, q, noise=SIGMA, seed=3)
    assert meas.positions.shape == (60, 2, 3)
    cal = cc.identify(robot, meas, "all", "gauss-newton")  # reflector positions not given
    assert cal.success, cal.message
    assert holdout_rms(cal, true, robot) < 1.1 * SIGMA * np.sqrt(3)
    # the reflectors' layout is found; their coordinates only up to the tool frame's own
    # rotation, so compare the frame-free distance between them
    found = np.array(cal.robot.points)
    assert np.linalg.norm(found[0] - found[1]) == pytest.approx(
        np.linalg.norm(np.subtract(*reflectors)), abs=0.05e-3
    )
    # two points fix the tool's orientation except the roll about the line between them
    assert "tool_x" in cal.unidentifiable  # redundant with the reflectors' positions
    assert "points started at the tool origin" in str(cal.summary())


def test_one_point_and_orientation():
    robot = cc.load_robot("puma560")
    true = robot.with_deviations(realistic_truth(robot, seed=7))
    q = cc.poses.uniform(robot, 60, seed=2)
    sigma_rot = np.deg2rad(0.005)
    meas = cc.simulate(true, q, noise=SIGMA, seed=3, orientation_noise=sigma_rot)
    assert meas.orientations.shape == (60, 3, 3)
    cal = cc.identify(robot, meas, "all", "gauss-newton")
    assert cal.success, cal.message
    assert holdout_rms(cal, true, robot) < 1.1 * SIGMA * np.sqrt(3)
    # with orientation measured, the tool's rotation moves what is measured (no zero
    # columns any more); it can still share a blind group with the last joint's θ6 and α6
    zero = {s.members[0] for s in cal.observability.blind_spots if "column is zero" in s.text}
    assert not {"tool_rx", "tool_ry", "tool_rz"} & zero
    rot_rms = np.sqrt(np.mean(np.sum(cal.orientation_residuals**2, axis=1)))
    assert rot_rms < 1.2 * sigma_rot * np.sqrt(3)


def test_robust_loss_and_outlier_list():
    robot = cc.load_robot("puma560")
    truth = realistic_truth(robot, seed=8)
    true = robot.with_deviations(truth)
    q = cc.poses.uniform(robot, 80, seed=2)
    meas = cc.simulate(true, q, noise=SIGMA, seed=3)
    bad = [3, 17, 40, 41, 66]  # gross errors: a reflector knocked, a beam broken
    y = meas.positions.copy()
    y[bad] += np.random.default_rng(9).normal(scale=2e-3, size=(len(bad), 3))
    dirty = cc.Measurements(q, y, SIGMA)
    plain = cc.identify(robot, dirty, "all", "gauss-newton")
    robust = cc.identify(robot, dirty, "all", "gauss-newton", loss="huber")
    # the robust fit finds them all; least squares spreads the gross errors over every
    # residual and can mask the smallest (1.3 mm here), but never accuses a good pose
    assert set(robust.outliers) == set(bad)
    assert set(plain.outliers) <= set(bad) and len(plain.outliers) >= 3
    floor = SIGMA * np.sqrt(3)
    assert holdout_rms(robust, true, robot) < 1.3 * floor
    assert holdout_rms(plain, true, robot) > 2 * holdout_rms(robust, true, robot)
    text = str(robust.summary())
    assert "huber" in text and "stand out" in text


def test_calibrated_robot_file_reproduces_the_calibrated_positions(tmp_path):
    robot = cc.load_robot("rx90b")
    true = robot.with_deviations(realistic_truth(robot, seed=10)).with_points([[0.05, 0, 0.1]])
    q = cc.poses.uniform(robot, 40, seed=1)
    cal = cc.identify(robot, cc.simulate(true, q, noise=SIGMA, seed=2), "all", "lm")
    path = tmp_path / "calibrated.toml"
    path.write_text(cc.robot_to_toml(cal.robot))
    again = cc.load_robot(path)
    q_new = cc.poses.uniform(robot, 300, seed=3)
    np.testing.assert_allclose(
        again.measured_points(q_new), cal.robot.measured_points(q_new), rtol=0, atol=1e-12
    )


def test_rotation_vector_up_to_pi():
    from casecal.data.measurements import rotation_from_vector, rotation_vector

    rng = np.random.default_rng(0)
    axes = rng.normal(size=(50, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    for angle in (1e-9, 0.3, np.pi - 1e-6, np.pi - 1e-9):
        w = axes * angle
        back = rotation_vector(rotation_from_vector(w))
        # at exactly pi the sign of the axis is a convention; away from it, exact
        np.testing.assert_allclose(np.linalg.norm(back, axis=1), angle, rtol=1e-6, atol=1e-12)
        if angle < 3:
            np.testing.assert_allclose(back, w, atol=1e-9)


def test_orientation_sigma_needs_position_sigma_and_rotations_are_proper():
    robot = cc.load_robot("puma560")
    q = cc.poses.uniform(robot, 20, seed=0)
    meas = cc.simulate(robot, q, orientation_noise=0.0)
    with pytest.raises(cc.CalibrationError, match="position sigma too"):
        cc.identify(robot, meas, orientation_sigma=1e-4)
    with pytest.raises(cc.CalibrationError, match="det"):
        cc.Measurements(q, meas.positions, 0.0, orientations=np.tile(-np.eye(3), (20, 1, 1)))


def test_validation_refuses_to_compare_across_frames():
    robot = cc.load_robot("puma560")
    two = cc.simulate(robot.with_deviations({"base_x": 2.0}), cc.poses.uniform(robot, 2, seed=0))
    with pytest.raises(cc.CalibrationError, match="refit the frames"):
        cc.validate(robot, two, robot)


def test_summary_says_when_the_model_does_not_fit_the_noise():
    robot = cc.load_robot("puma560")
    true = robot.with_deviations({"base_x": 0.01, "a2": 2e-4})  # a base offset not asked for
    meas = cc.simulate(true, cc.poses.uniform(robot, 40, seed=0), noise=SIGMA, seed=1)
    cal = cc.identify(robot, meas, ["theta*", "a*"], "gauss-newton")
    assert cal.reduced_chi2 > 4
    # a fit that cannot reach its noise is a failure, and says why
    assert not cal.success and cal.status == -2
    assert "residual consistent with the noise" in [c.name for c in cal.audit.failures]
    assert "FAIL residual consistent with the noise: reduced χ²" in str(cal.summary())
    # with the base frame asked for, the same data fit down to the noise
    fine = cc.identify(robot, meas, ["theta*", "d*", "a*", "alpha*", "base_*"], "gauss-newton")
    assert fine.reduced_chi2 < 2 and fine.success and fine.audit.passed
    assert "ok   residual consistent with the noise: reduced χ²" in str(fine.summary())
