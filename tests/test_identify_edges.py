"""Weighting, other conventions and joint types, and every user mistake ending in one message."""

from __future__ import annotations

import numpy as np
import pytest

import casecal as cc
from casecal.cli import main
from casecal.data.files import read_csv

DH = ["theta*", "d*", "a*", "alpha*"]


def test_per_axis_sigma_weights_the_fit_as_the_textbook_covariance_says():
    """Standard errors with per-axis sigma equal (Jᵀ Σ⁻¹ J)⁻¹ computed here from the
    robot's own Jacobian, and grow when one axis is noisier."""
    robot = cc.load_robot("puma560")
    q = cc.poses.uniform(robot, 50, seed=0)
    # deviations well above the noise, so that both weightings estimate the same set
    meas = cc.simulate(robot.with_deviations({"a2": 0.5e-3, "theta3": 2e-3, "d4": -0.5e-3}), q)
    sigma = np.array([0.01e-3, 0.01e-3, 0.1e-3])  # z ten times noisier
    cal = cc.identify(robot, meas, ["theta*", "a*", "d*"], "gauss-newton", noise=sigma)
    J, names = cal.robot.position_jacobian(q, list(cal.estimated))
    Jw = (J / sigma[None, :, None]).reshape(-1, len(names))
    expected = np.sqrt(np.diag(np.linalg.inv(Jw.T @ Jw)))
    got = np.array([cal.standard_errors[n] for n in names])
    np.testing.assert_allclose(got, expected, rtol=1e-6)
    iso = cc.identify(robot, meas, ["theta*", "a*", "d*"], "gauss-newton", noise=0.01e-3)
    assert iso.estimated == cal.estimated
    assert all(cal.standard_errors[n] >= iso.standard_errors[n] * (1 - 1e-9) for n in names)


@pytest.mark.parametrize("name", ["puma560_craig", "scara"])
def test_modified_dh_and_prismatic_robots_are_identified_exactly(name):
    robot = cc.load_robot(name)
    q = cc.poses.uniform(robot, 80, seed=1)
    obs = cc.observability(robot, q, DH)
    rng = np.random.default_rng(2)
    truth = {n: rng.normal(scale=1e-4) for n in obs.identifiable}
    meas = cc.simulate(robot.with_deviations(truth), q)
    for method in ("gauss-newton", "lm", "ipopt"):
        cal = cc.identify(robot, meas, DH, method, truth=truth)
        assert cal.success and cal.rms < 1e-12, (name, method, cal.message)
        for n in truth:
            assert cal.deviations[n] == pytest.approx(truth[n], rel=1e-6, abs=1e-12), (name, n)


def test_blind_directions_and_visible_combinations_carry_their_units():
    """A null vector δp has member/lead units; a visible combination lead/member units."""
    puma = cc.load_robot("puma560")
    obs = cc.observability(puma, cc.poses.seed_schedule(puma, 100), "all")
    spot = next(s for s in obs.blind_spots if set(s.members) == {"theta3", "a3", "d4"})
    assert spot.blind == ("theta3 + 0.4318 m/rad·a3 - 0.0203 m/rad·d4",)
    # check the direction numerically: J · (1 rad, 0.4318 m, -0.0203 m) vanishes
    J, _ = puma.position_jacobian(cc.poses.seed_schedule(puma, 100), ["theta3", "a3", "d4"])
    assert np.abs(J @ np.array([1.0, 0.4318, -0.0203])).max() < 1e-4 * np.abs(J).max()
    scorbot = cc.load_robot("scorbot")
    obs = cc.observability(scorbot, cc.poses.uniform(scorbot, 50, seed=0))
    spot = next(s for s in obs.blind_spots if set(s.members) == {"theta4", "a4"})
    assert spot.visible.startswith("theta4 + 6.891 rad/m·a4")
    assert spot.visible_as("a4").startswith("a4 + 0.1451 m/rad·theta4")


def test_ill_posed_pose_set_is_held_and_named_not_silently_identified():
    """The paper's schedule at 10 poses sweeps only 9°: with noise the paper's one-shot
    estimates are metres off (17 mm on new poses here); the iterated fit holds what the
    poses cannot determine at nominal and names it. Both say they failed: the poses do
    not support the parameters asked for."""
    robot = cc.load_robot("scorbot")  # the truth is the nominal robot
    meas = cc.simulate(robot, cc.poses.seed_schedule(robot, 10), noise=0.01e-3, seed=1)
    q_new = cc.poses.uniform(robot, 300, seed=5)

    def error_on_new_poses(cal):
        e = np.linalg.norm(cal.robot.position(q_new) - robot.position(q_new), axis=1)
        return np.sqrt(np.mean(e**2))

    one_shot = cc.identify(robot, meas, None, "svd")
    assert not one_shot.success and error_on_new_poses(one_shot) > 1e-2
    assert "prediction no worse than uncalibrated" in [c.name for c in one_shot.audit.failures]

    cal = cc.identify(robot, meas, None, "gauss-newton")
    assert not cal.success
    assert [c.name for c in cal.audit.failures] == ["prediction no worse than uncalibrated"]
    # metres and thousands of degrees: held at nominal and named, not estimated
    assert {"d5", "theta5", "theta4"} <= set(cal.pruned)
    assert all(cal.deviations[n] == 0.0 for n in cal.pruned)
    assert error_on_new_poses(cal) < 0.02e-3  # m: holding kept the robot near nominal
    text = str(cal.summary())
    assert "because these data do not determine them" in text and "FAILED" in text
    for name in cal.pruned:
        assert name in text
        assert cal.table.set_index("parameter").status[name].startswith("held: not determined")


@pytest.mark.parametrize(
    ("call", "needle"),
    [
        (lambda r, m: cc.identify(r, m, []), "no parameters"),
        (lambda r, m: cc.identify(r, m, 5), "not understood"),
        (lambda r, m: cc.identify(r, m, ["theta5"], "lm"), "none of the asked-for"),
        (lambda r, m: cc.identify(r, m, method="ipopt", bounds={"a2": 1e-3}), "bounds"),
        (lambda r, m: cc.identify(r, m, method="ipopt", bounds={"a2": (1, -1)}), "lower"),
        (lambda r, m: cc.identify(r, m, method="ipopt", noise=1e-5, prior={"a2": 0.0}), "> 0"),
        (lambda r, m: cc.identify(r, m, method="ipopt", noise=1e-5, prior={"a2": -1}), "> 0"),
        (lambda r, m: cc.identify(r, m, max_iterations=0), "max_iterations"),
        (lambda r, m: cc.identify(r, m, noise=[1e-5, 2e-5]), "does not fit"),
        (lambda r, m: cc.simulate(r, m.q, noise="0.01mm"), "does not fit"),
        (lambda r, m: r.with_deviations({"a2": "x"}), "not a number"),
        (lambda r, m: r.with_deviations({"a2": None}), "not a number"),
        (lambda r, m: r.fk(np.zeros((0, 5))), "N >= 1"),
        (lambda r, m: cc.Measurements(np.zeros((0, 5)), np.zeros((0, 3)), 0.0), "N >= 1"),
        (lambda r, m: cc.Measurements(np.full((2, 5), np.nan), np.zeros((2, 3)), 0.0), "finite"),
    ],
)
def test_user_mistakes_raise_calibration_error(call, needle):
    robot = cc.load_robot("scorbot")
    meas = cc.simulate(robot, cc.poses.uniform(robot, 30, seed=0))
    with pytest.raises(cc.CalibrationError) as info:
        call(robot, meas)
    assert needle in str(info.value)


def test_csv_sigma_columns_in_micrometres_and_unrelated_sigma_columns(tmp_path):
    robot = cc.load_robot("rr")
    path = tmp_path / "m.csv"
    path.write_text("q1,q2,x_um,y_um,z_um,sigma_um,sigma_note\n0.1,0.2,1.9e6,3e5,0,20,laser\n")
    meas = read_csv(path, robot)
    np.testing.assert_allclose(meas.positions, [[1.9, 0.3, 0.0]])
    np.testing.assert_allclose(meas.sigma, np.full((1, 3), 20e-6))


def test_cli_output_folders(tmp_path, capsys):
    # a missing folder is created; a path through a file is one line and exit 2
    target = tmp_path / "new" / "x.csv"
    assert main(["simulate", "scorbot", "--poses", "5", "-o", str(target)]) == 0
    assert target.is_file()
    blocked = tmp_path / "file"
    blocked.write_text("")
    code = main(["simulate", "scorbot", "--poses", "5", "-o", str(blocked / "x.csv")])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("casecal: error:") and err.count("\n") == 1


def test_robust_fit_without_sigma_counts_only_the_poses_it_kept():
    """Standard errors of a Huber fit with outliers left out equal those of a fit of the
    clean poses alone: zero-weight rows are no degrees of freedom (they were 0.83x)."""
    robot = cc.load_robot("puma560")
    true = robot.with_deviations({"a2": 2e-4, "d3": -1e-4, "theta2": 1e-4, "a3": -2e-4})
    q = cc.poses.uniform(robot, 200, seed=0)
    y = cc.simulate(true, q, noise=2e-5, seed=1).positions.copy()
    rng = np.random.default_rng(5)
    bad = rng.choice(200, 60, replace=False)
    y[bad] += rng.normal(0, 2e-3, size=y[bad].shape)
    keep = np.setdiff1d(np.arange(200), bad)
    robust = cc.identify(robot, cc.Measurements(q, y, 0.0), loss="huber")
    clean = cc.identify(robot, cc.Measurements(q[keep], y[keep], 0.0))
    assert robust.success and clean.success and len(robust.outliers) == 60
    for name in ("a2", "theta2", "a3"):
        assert robust.standard_errors[name] == pytest.approx(clean.standard_errors[name], rel=1e-6)


@pytest.mark.parametrize("option", ["bounds", "prior"])
def test_bounds_and_priors_on_the_base_are_refused_not_ignored(option):
    """The base is fitted from a rigid fit of the data: a bound on base_x used to end
    1 mm outside it with the audit saying no estimate sat on its bounds."""
    robot = cc.load_robot("puma560")
    true = robot.with_deviations({"a2": 2e-4, "base_x": 1e-3})
    meas = cc.simulate(true, cc.poses.uniform(robot, 100, seed=0), noise=2e-5, seed=1)
    value = {"bounds": {"base_x": (0.0, 5e-4)}, "prior": {"base_x": 1e-5}}[option]
    with pytest.raises(cc.CalibrationError, match="base frame"):
        cc.identify(robot, meas, "all", "ipopt", **{option: value})
