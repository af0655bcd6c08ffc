"""Joint couplings ``q_model = M q_controller + b`` (`Robot.with_coupling`, ``[coupling]``).

Every joint value a user gives or gets is the controller's; the kinematics is the model's.
The references are independent of the coupling code: the uncoupled robot's forward
kinematics at ``M q + b`` computed here with numpy, finite differences of the tool pose in
controller joints, the simulated truth.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import casecal as cc
from casecal.cli import main
from casecal.data.files import read_csv, write_csv
from casecal.model.compensate_solve import joint_jacobian

DEV = {
    "theta2": 1e-3,
    "a2": 5e-4,
    "d4": -3e-4,
    "theta3": -2e-3,
    "alpha3": 1e-3,
    "a1": 4e-4,
    "d6": 2e-4,
    "theta5": 1e-3,
}


def parallelogram(offset_deg: float = 90.0):
    """A KR 16 whose model joint 3 turns by -(J2 + J3) + offset: the controller's J3 is
    the forearm's angle, the model's the elbow's."""
    robot = cc.load_robot("kr16_2")
    M = np.eye(6)
    M[2, 1] = M[2, 2] = -1.0
    b = np.zeros(6)
    b[2] = math.radians(offset_deg)
    return robot, M, b, robot.with_coupling(M, b)


TORSO_TOML = """\
name = "torso"
convention = "dh"
length_unit = "mm"
angle_unit = "deg"
[[joints]]
type = "R"
a = 0.0
alpha = -90.0
d = 120.0
[[joints]]
type = "R"
a = 150.0
alpha = 0.0
d = 0.0
[[joints]]
type = "R"
a = 150.0
alpha = 0.0
d = 0.0
[[joints]]
type = "R"
a = 80.0
alpha = 0.0
d = 0.0
[tool]
xyz = [30.0, 10.0, 40.0]
[coupling]                 # the passive joint keeps the last link level: q4 = -(q2 + q3)
controller_joints = 3
q4 = {q2 = -1.0, q3 = -1.0, offset = 5.0}
limits = [[-60.0, 60.0], [-40.0, 40.0], []]
"""


RANK_DEFICIENT = "q4 = {q3 = 1.0}\nq1 = {q1 = 1.0, q2 = 1.0}\nq2 = {q1 = 1.0, q2 = 1.0}"


# --- kinematics ------------------------------------------------------------------------


def test_fk_is_the_uncoupled_robots_at_the_model_joints():
    robot, M, b, coupled = parallelogram()
    q = cc.poses.uniform(coupled, 50, seed=3)
    q_model = q @ M.T + b  # by hand: the spec
    np.testing.assert_array_equal(coupled.model_joints(q), q_model)
    np.testing.assert_allclose(coupled.fk(q), robot.fk(q_model), rtol=0, atol=1e-15)
    np.testing.assert_allclose(coupled.fk(q[0]), robot.fk(q_model[0]), rtol=0, atol=1e-15)
    np.testing.assert_allclose(coupled.position(q), robot.position(q_model), rtol=0, atol=1e-15)
    J, names = coupled.position_jacobian(q, "all")
    J0, names0 = robot.position_jacobian(q_model, "all")
    assert names == names0
    np.testing.assert_allclose(J, J0, rtol=0, atol=1e-15)
    # and not the same robot: the controller's J3 is not the model's
    assert np.abs(coupled.position(q) - robot.position(q)).max() > 0.1
    # no part of the kinematics graph: same structure, same kernels, same parameters
    assert coupled.structure == robot.structure
    assert coupled.parameter_names == robot.parameter_names
    assert coupled.dof == coupled.model_dof == 6


def test_joint_jacobian_is_the_controllers():
    """The compensation's joint Jacobian (model Jacobian times M) against central
    differences of the tool pose in controller joints."""
    _, _, _, coupled = parallelogram()
    q = cc.poses.uniform(coupled, 4, seed=5)
    J = joint_jacobian(coupled, q, slice(None))
    h = 1e-6
    for k in range(6):
        step = np.zeros(6)
        step[k] = h
        plus, minus = coupled.fk(q + step), coupled.fk(q - step)
        dp = (plus[:, :3, 3] - minus[:, :3, 3]) / (2 * h)
        np.testing.assert_allclose(J[:, :3, k], dp, rtol=0, atol=1e-8)
        dR = (plus[:, :3, :3] - minus[:, :3, :3]) / (2 * h)
        W = dR @ np.transpose(coupled.fk(q)[:, :3, :3], (0, 2, 1))  # skew(ω)
        omega = np.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], axis=1)
        np.testing.assert_allclose(J[:, 3:, k], omega, rtol=0, atol=1e-8)


def test_identity_is_no_coupling():
    robot = cc.load_robot("kr16_2")
    assert robot.with_coupling(np.eye(6)) == robot
    assert robot.coupling is None and robot.model_joints(np.zeros(6)).shape == (6,)


# --- identification and compensation ---------------------------------------------------


def test_identify_and_compensate_in_controller_joints():
    """Simulated in controller joints, identified, compensated: the true (coupled) robot
    sent the compensated values reaches the nominal robot's pose at the targets."""
    robot, _, _, nominal = parallelogram()
    true = nominal.with_deviations(DEV)
    meas = cc.simulate(true, cc.poses.uniform(nominal, 100, seed=1), noise=1e-6, seed=2)
    cal = cc.identify(nominal, meas, "all", noise=1e-6, truth=DEV)
    assert cal.success
    assert cal.nominal == nominal and cal.robot.coupling == nominal.coupling
    np.testing.assert_array_equal(cal.robot.limits, nominal.limits)
    alone = [n for n in DEV if n in cal.estimated and cal.stands_for(n) == n]
    assert len(alone) >= 5
    for name in alone:
        assert abs(cal.deviations[name] - DEV[name]) < 5 * cal.standard_errors[name], name
    # the same data read with the model's joints for the controller's do not fit
    assert not cc.identify(robot, meas, "all", noise=1e-6).success

    q_t = cc.poses.uniform(nominal, 40, seed=7)
    comp = cc.compensate(cal.robot, q_t, nominal=nominal, frame="instrument")
    assert comp.ok.mean() >= 0.9
    target = nominal.fk(q_t)
    reached = true.fk(comp.q)
    ok = comp.ok
    assert np.abs(reached[ok, :3, 3] - target[ok, :3, 3]).max() < 1e-5  # 10 µm
    before = np.abs(true.fk(q_t)[ok, :3, 3] - target[ok, :3, 3]).max()
    assert before > 1e-3  # uncompensated: a millimetre or more off
    lo, hi = nominal.limits.T
    assert np.all((comp.q[ok] >= lo) & (comp.q[ok] <= hi))


def test_torso_with_a_passive_joint(write_toml):
    """Four model joints, three controller joints (q4 = -(q2 + q3) + 5°): limits bound the
    controller joints; identify and compensate (position) speak the controller's three."""
    torso = cc.load_robot(write_toml(TORSO_TOML))
    assert (torso.dof, torso.model_dof, torso.controller_types) == (3, 4, "RRR")
    np.testing.assert_allclose(
        torso.limits, np.radians([[-60, 60], [-40, 40], [-180, 180]]), rtol=1e-15
    )
    q = cc.poses.uniform(torso, 200, seed=0)
    assert q.shape == (200, 3)
    assert np.all(np.abs(q[:, 0]) <= math.radians(60)) and np.all(np.abs(q[:, 1]) <= 0.7)
    q4 = q[:, 1] * -1 - q[:, 2] + math.radians(5)
    np.testing.assert_allclose(torso.model_joints(q)[:, 3], q4, rtol=0, atol=1e-15)
    # the uncoupled model's joint ranges are where the controller's box maps them
    hull = torso.uncoupled().limits
    assert hull[3][0] == pytest.approx(math.radians(5 - 40 - 180), rel=1e-12)
    assert hull[3][1] == pytest.approx(math.radians(5 + 40 + 180), rel=1e-12)

    dev = {"a2": 2e-3, "a3": -1.5e-3, "theta2": 2e-3, "a4": 1e-3, "theta4": -3e-3}
    true = torso.with_deviations(dev)
    meas = cc.simulate(true, q, noise=1e-5, seed=1)
    cal = cc.identify(torso, meas, ["a2", "a3", "a4", "theta2", "theta4"], noise=1e-5)
    assert cal.success
    for name, value in dev.items():
        assert abs(cal.deviations[name] - value) < 5 * cal.standard_errors[name], name
    q_t = cc.poses.uniform(torso, 20, seed=9)
    comp = cc.compensate(cal.robot, q_t, nominal=torso, frame="instrument")
    assert comp.q.shape == (20, 3) and comp.ok.mean() >= 0.75
    err = true.position(comp.q[comp.ok]) - torso.position(q_t[comp.ok])
    assert np.abs(err).max() < 2e-5
    # the rows refused leave the controller's limits (joint 2: ±40°), not the model's
    refused = [r for r in comp.reason if r]
    assert refused and all(r.startswith("outside the limits of joint 2") for r in refused)
    assert all("beyond its limit 40°" in r or "beyond its limit -40°" in r for r in refused)


def test_compensate_refuses_a_nominal_coupled_otherwise():
    robot, _, _, coupled = parallelogram()
    with pytest.raises(cc.CalibrationError, match="couple their joints differently"):
        cc.compensate(coupled, np.zeros(6), nominal=robot)


# --- limits ----------------------------------------------------------------------------


def test_limits_bound_the_controller_joints():
    """As many controller as model joints: the rows' limits, row i for controller joint i,
    what poses are drawn in and what the CSV warns about."""
    robot, _, _, coupled = parallelogram()
    np.testing.assert_array_equal(coupled.limits, robot.limits)
    q = cc.poses.uniform(coupled, 500, seed=0)
    assert np.all((q >= robot.limits[:, 0]) & (q <= robot.limits[:, 1]))
    # the model's joint 3 goes where the controller's joints take it, beyond row 3's range
    q3 = coupled.model_joints(q)[:, 2]
    assert q3.max() > robot.limits[2, 1] or q3.min() < robot.limits[2, 0]


# --- files -----------------------------------------------------------------------------


def test_csv_columns_are_the_controllers(tmp_path, write_toml):
    torso = cc.load_robot(write_toml(TORSO_TOML))
    q = cc.poses.uniform(torso, 10, seed=0)
    meas = cc.simulate(torso, q, noise=0.0)
    path = tmp_path / "m.csv"
    write_csv(path, meas, torso)
    header = path.read_text().splitlines()[0]
    assert header.startswith("q1_deg,q2_deg,q3_deg,x_mm")
    back = read_csv(path, torso)
    np.testing.assert_allclose(back.q, q, rtol=1e-14, atol=1e-15)
    lines = path.read_text().splitlines()
    rows = [lines[0].replace("q3_deg", "q3_deg,q4_deg")]
    for line in lines[1:]:  # a fourth joint column: the model's passive joint
        cells = line.split(",")
        rows.append(",".join([*cells[:3], "0", *cells[3:]]))
    path.write_text("\n".join(rows) + "\n")
    with pytest.raises(cc.CalibrationError, match="has 3 joints"):
        read_csv(path, torso)


def test_toml_round_trip(tmp_path, write_toml):
    _, _, _, coupled = parallelogram(offset_deg=12.5)
    path = tmp_path / "arm.toml"
    assert cc.save_robot(coupled, path) == []
    back = cc.load_robot(path)
    assert back == coupled and back.coupling == coupled.coupling
    assert "[coupling]" in path.read_text()
    torso = cc.load_robot(write_toml(TORSO_TOML))
    cc.save_robot(torso, tmp_path / "torso.toml")
    again = cc.load_robot(tmp_path / "torso.toml")
    assert again == torso
    np.testing.assert_array_equal(again.coupling.M, [[1, 0, 0], [0, 1, 0], [0, 0, 1], [0, -1, -1]])
    assert again.coupling.b[3] == pytest.approx(math.radians(5), rel=1e-15)


def test_toml_in_degrees(write_toml):
    text = TORSO_TOML.replace(
        "q4 = {q2 = -1.0, q3 = -1.0, offset = 5.0}", "q4 = {q2 = -0.5, q3 = -1.0}"
    )
    torso = cc.load_robot(write_toml(text))
    np.testing.assert_array_equal(torso.coupling.M[3], [0.0, -0.5, -1.0])
    assert torso.coupling.b[3] == 0.0
    np.testing.assert_allclose(torso.coupling.limits[1], np.radians([-40, 40]), rtol=1e-15)
    assert torso.coupling.limits[2] is None


@pytest.mark.parametrize(
    ("edit", "needle"),
    [
        (("controller_joints = 3\n", "controller_joints = 5\n"), "from 1 to the model's 4"),
        (("q4 = {", "q5 = {"), "unknown key 'q5'"),
        (("q4 = {q2 = -1.0, q3 = -1.0, offset = 5.0}\n", ""), "does not give model joint q4"),
        (("q4 = {q2", "q4 = {q7"), "no controller joint"),
        (("limits = [[-60.0, 60.0], [-40.0, 40.0], []]", "limits = [[1.0, 2.0]]"), "one"),
        (("d = 120.0\n", "d = 120.0\nlimits = [-90.0, 90.0]\n"), "must not carry any"),
        (("q4 = {q2 = -1.0, q3 = -1.0, offset = 5.0}", RANK_DEFICIENT), "rank"),
    ],
)
def test_toml_refuses(write_toml, edit, needle):
    assert edit[0] in TORSO_TOML
    with pytest.raises(cc.CalibrationError) as info:
        cc.load_robot(write_toml(TORSO_TOML.replace(*edit)))
    assert needle in str(info.value)


def test_toml_coupling_must_be_a_table(write_toml):
    text = "coupling = 3\n" + TORSO_TOML.split("[coupling]")[0]
    with pytest.raises(cc.CalibrationError, match="coupling must be a table"):
        cc.load_robot(write_toml(text))


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        ((np.eye(5),), "shape (5, 5)"),
        ((np.eye(6)[:, :7].repeat(2, axis=1),), "12 controller joints for 6"),
        ((np.c_[np.eye(6)[:, :5], np.zeros(6)],), "drives no model joint"),
        ((np.full((6, 6), np.nan),), "non-finite"),
        ((np.eye(6), np.ones(5)), "6 finite numbers"),
        ((np.eye(6), None, [(0.0, 1.0)] * 6), "the model's joint rows carry the limits"),
    ],
)
def test_with_coupling_refuses(args, needle):
    with pytest.raises(cc.CalibrationError) as info:
        cc.load_robot("kr16_2").with_coupling(*args)
    assert needle in str(info.value)


def test_mixed_joint_types_refused():
    scara = cc.load_robot("scara")  # RRPR
    M = np.eye(4)
    M[2, 1] = 1.0  # the prismatic joint driven by a revolute one
    with pytest.raises(cc.CalibrationError, match="revolute and prismatic"):
        scara.with_coupling(M)


def test_exports_that_cannot_hold_it_refuse(tmp_path):
    _, _, _, coupled = parallelogram()
    for name in ("arm.urdf", "arm.yaml"):
        with pytest.raises(cc.CalibrationError, match="couples its joints") as info:
            cc.save_robot(coupled, tmp_path / name)
        assert "save as .toml" in str(info.value)
        assert not (tmp_path / name).exists()
    ur = cc.load_robot("ur5e")
    M = np.eye(6)
    M[2, 1] = -1.0
    with pytest.raises(cc.CalibrationError, match="cannot hold that"):
        cc.save_robot(ur.with_coupling(M), tmp_path / "ur.yaml")


def test_command_line(tmp_path, capsys):
    """simulate, identify -o and compensate with a coupled robot file; a URDF output is
    refused before the fit."""
    _, _, _, coupled = parallelogram()
    robot = tmp_path / "arm.toml"
    cc.save_robot(coupled, robot)
    dev = tmp_path / "dev.toml"
    dev.write_text("[deviations]\ntheta2 = 0.001\na2 = 0.0005\ntheta3 = -0.002\n")
    meas = tmp_path / "m.csv"
    argv = ["simulate", str(robot), "--schedule", "uniform", "--poses", "60"]
    assert main([*argv, "--deviations", str(dev), "--noise", "0.001mm", "-o", str(meas)]) == 0
    out = tmp_path / "cal.urdf"
    assert main(["identify", str(robot), str(meas), "-o", str(out)]) == 2
    assert "couples its joints" in capsys.readouterr().err and not out.exists()
    out = tmp_path / "cal.toml"
    assert main(["identify", str(robot), str(meas), "-o", str(out)]) == 0
    calibrated = cc.load_robot(out)
    assert calibrated.coupling == coupled.coupling
    assert main(["show", str(out)]) == 0
    assert "model q3 = -q2 - q3 + 90°" in capsys.readouterr().out
    targets = tmp_path / "t.csv"
    write_csv(targets, cc.simulate(coupled, cc.poses.uniform(coupled, 5, seed=4)), coupled)
    result = tmp_path / "c.csv"
    assert main(["compensate", str(out), str(targets), "-o", str(result)]) == 0
    assert result.read_text().startswith("q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,ok")


def test_distances_and_validation_in_controller_joints():
    from casecal.identification.distances import (
        identify_distances,
        random_pairs,
        simulate_distances,
    )

    _, _, _, coupled = parallelogram()
    dev = {"a2": 1e-3, "theta3": 2e-3}
    true = coupled.with_deviations(dev)
    q = cc.poses.uniform(coupled, 60, seed=1)
    measured = simulate_distances(true, q, random_pairs(60, 400, seed=2), noise=1e-6, seed=3)
    cal = identify_distances(coupled, measured, ["a2", "theta3", "a3"])
    assert cal.success and cal.robot.coupling == coupled.coupling
    for name, value in dev.items():
        assert abs(cal.deviations[name] - value) < 5 * cal.standard_errors[name], name
    held_out = cc.simulate(true, cc.poses.uniform(coupled, 60, seed=4), noise=1e-6, seed=5)
    check = cc.validate(cal.robot, held_out, coupled)
    assert check.after.rms < 5e-6 < 1e-3 < check.before.rms


def test_a_passive_joint_passes_the_audit_with_the_default_and_all(write_toml):
    """The audit's workspace poses are the coupled robot's (controller joints through the
    coupling): drawn from the model's hull, the passive joint moved on its own there and
    the audit failed a fit 0.002 mm from the truth, saying poses across the joint ranges
    would see theta4 and a4, which no pose of this robot can (review of issue 21)."""
    torso = cc.load_robot(write_toml(TORSO_TOML))
    true = torso.with_deviations({"a2": 1e-3, "a4": -1e-3, "theta2": 1e-3})
    meas = cc.simulate(true, cc.poses.uniform(torso, 200, seed=1), 1e-5, seed=2)
    q_t = cc.poses.uniform(torso, 300, seed=8)
    for parameters in (None, "all"):
        cal = cc.identify(torso, meas, parameters)
        assert cal.success, cal.message
        error = np.linalg.norm(cal.robot.position(q_t) - true.position(q_t), axis=-1)
        assert error.mean() < 2e-5 < np.linalg.norm(torso.position(q_t) - true.position(q_t))
    model = torso.uncoupled()
    q_model = cc.poses.uniform(model, 50, seed=0)
    np.testing.assert_allclose(
        q_model[:, 3], -q_model[:, 1] - q_model[:, 2] + math.radians(5), rtol=0, atol=1e-15
    )
    assert cal.robot.coupled_from is None and model.recoupled(torso) == torso


def test_a_coupled_robot_with_sessions_has_its_summary():
    """`cal.nominal` of a coupled fit keeps the sessions' frames: the summary and the table
    looked the later sessions' names up in a nominal without them (KeyError)."""
    _, _, _, coupled = parallelogram()
    true = coupled.with_deviations({"a2": 4e-4})
    labels = np.repeat(["mon", "tue"], 60)
    tue = ((2.0, 0.5, 0.1), (0.0, 0.0, 1.2))
    meas = cc.simulate(
        true,
        cc.poses.uniform(coupled, 120, seed=1),
        2e-5,
        seed=2,
        session=labels,
        frames={"tue": tue},
    )
    cal = cc.identify(coupled, meas)
    assert cal.success and "base_x@tue" in set(cal.table["parameter"])
    assert "tue" in str(cal.summary())
    np.testing.assert_allclose(cal.sessions["tue"].base.xyz, tue[0], atol=1e-4)
    held = cc.simulate(true, cc.poses.uniform(coupled, 40, seed=5), 2e-5, seed=3)
    assert cc.validate(cal.robot, held, cal.nominal).after.rms < 5e-5


def test_a_urdf_tree_takes_a_passive_joint():
    """A URDF's joints all carry limits: with fewer controller joints, each takes those of
    the model joint it drives one to one (refused before: the rows must carry none)."""
    urdf = Path(__file__).parents[1] / "examples" / "two_arms.urdf"
    tree = cc.load_robot(urdf, tip_link=["right_marker", "left_marker"])
    n = tree.model_dof
    M = np.zeros((n, n - 1))
    M[: n - 1, : n - 1] = np.eye(n - 1)
    M[n - 1, 0] = -1.0  # the last joint turns back by the first
    coupled = tree.with_coupling(M, b=np.r_[np.zeros(n - 1), 0.1])
    # joint 1 bounded so that the joint it drives back (-q1 + 0.1) stays in its limits too
    np.testing.assert_allclose(coupled.limits[0], tree.limits[0] + [0.1, 0.0], rtol=0, atol=1e-15)
    np.testing.assert_array_equal(coupled.limits[1:], tree.limits[1 : n - 1])
    assert all(j.limits is None for j in coupled.joints)
    q = cc.poses.uniform(coupled, 120, seed=1)
    true = coupled.with_deviations({"torso_yaw.x": 1e-3, "left_elbow.roll": 1e-3})
    cal = cc.identify(coupled, cc.simulate(true, q, 0.2e-3, seed=1))
    q_t = cc.poses.uniform(coupled, 100, seed=2)
    assert cal.success
    assert np.abs(cal.robot.position(q_t) - true.position(q_t)).max() < 1e-3
    with pytest.raises(cc.CalibrationError, match="drives no model joint alone"):
        tree.with_coupling(np.r_[np.eye(n - 1)[:-1], np.ones((2, n - 1))])
