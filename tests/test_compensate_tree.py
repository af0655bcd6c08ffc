"""Compensation over a kinematic tree (issue 22, item 6): per pose, every model joint solved
together so that each tip of the calibrated tree reaches where the nominal tree puts it
(its position, and its orientation where six or more joints move it), with error terms
(compliance, whose deflections depend on q) and couplings (controller joints in and out).

Every check is against the robots' own forward kinematics at the returned joints, never
against what the compensation reports of itself."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.optimize import minimize
from scipy.spatial.transform import Rotation

import casecal as cc
from casecal.cli import main
from casecal.model import kinematics

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "two_arms.urdf"
TIPS = ["right_marker", "left_marker"]


def two_arms(tmp_path=None, masses=False):
    """The example tree; with `masses`, a copy (in `tmp_path`) whose links weigh 1.5 kg each,
    centre of mass 5 cm off the link's frame, so that compliance has loads to bend under."""
    if not masses:
        return cc.load_robot(EXAMPLE, tip_link=TIPS)
    inertial = (
        '<inertial><origin xyz="0.02 0.01 0.05" rpy="0 0 0"/><mass value="1.5"/>'
        '<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>'
    )
    text = re.sub(
        r'<link name="([^"]+)"/>', rf'<link name="\1">{inertial}</link>', EXAMPLE.read_text()
    )
    path = tmp_path / "two_arms_masses.urdf"
    path.write_text(text)
    return cc.load_robot(path, tip_link=TIPS)


def deviated(robot, seed, length=1e-3, angle=0.5 * np.pi / 180, values=None):
    """`robot` with Gaussian deviations of `length` on every origin's x, y, z and `angle` on
    every roll, pitch, yaw and zero offset (the base left alone), and `values` set."""
    rng = np.random.default_rng(seed)
    deviations = {}
    for name in robot.parameter_names:
        field = name.rsplit(".", 1)[-1]
        if name.startswith("base"):
            continue
        if field in ("x", "y", "z"):
            deviations[name] = rng.normal(0, length)
        elif field in ("roll", "pitch", "yaw", "offset"):
            deviations[name] = rng.normal(0, angle)
    return robot.with_deviations({**deviations, **(values or {})})


def compliances(robot, value):
    """`value` (rad/(N·m)) for every joint compliance and lateral bending ``c{i}``,
    ``c{i}_u``, ``c{i}_v`` that `robot` has (a joint about the vertical carries no load)."""
    return {n: value for n in robot.parameter_names if re.fullmatch(r"c\d+(_[uv])?", n)}


def misses(real, q, nominal, nominal_q, X=None):
    """Per pose and tip: distance, m, and turn, rad, between `real`'s tips at `q` and where
    `nominal` (placed by `X`) puts them at `nominal_q`, from the robots' forward kinematics."""
    X = np.eye(4) if X is None else X
    got, want = real.fk(q), X @ nominal.fk(nominal_q)
    distance = np.linalg.norm(got[..., :3, 3] - want[..., :3, 3], axis=-1)
    R = want[..., :3, :3] @ np.swapaxes(got[..., :3, :3], -1, -2)
    turn = Rotation.from_matrix(R.reshape(-1, 3, 3)).magnitude().reshape(distance.shape)
    return distance, turn


def central_jacobian(robot, q, h=1e-6):
    """∂(tips' positions, rotations)/∂q by central differences of `robot.fk`: (6 · tips, dof),
    the rotation rows vee((R(q + h) - R(q - h)) / 2h · Rᵀ)."""
    R0 = robot.fk(q)[:, :3, :3]
    cols = []
    for i in range(robot.dof):
        dq = np.zeros(robot.dof)
        dq[i] = h
        plus, minus = robot.fk(q + dq), robot.fk(q - dq)
        dp = (plus[:, :3, 3] - minus[:, :3, 3]) / (2 * h)
        W = (plus[:, :3, :3] - minus[:, :3, :3]) / (2 * h) @ np.swapaxes(R0, -1, -2)
        omega = np.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], axis=1)
        cols.append(np.concatenate([dp, omega], axis=1).reshape(-1))
    return np.stack(cols, axis=1)


def test_the_tree_joint_jacobian_matches_differences_with_compliance(tmp_path):
    nominal = two_arms(tmp_path, masses=True).with_compliance(lateral=True)
    robot = deviated(nominal, 3, values=compliances(nominal, 2e-3))
    q = cc.poses.uniform(robot, 4, seed=5)
    J = kinematics.chain(robot.structure).evaluate("joint_jacobian", q, robot.vector())
    assert J.shape == (4, 12, 7)
    for k in range(4):
        np.testing.assert_allclose(J[k], central_jacobian(robot, q[k]), atol=1e-7)


@pytest.mark.parametrize("masses", [False, True])
def test_a_calibrated_tree_puts_every_tip_where_the_nominal_does(tmp_path, masses):
    """Two arms of 3 joints on a turning torso: 4 joints move each marker, so positions only;
    6 rows and 7 joints, the least correction. With masses the calibrated tree bends under
    gravity (joint and lateral compliance), its deflections a function of q."""
    nominal = two_arms(tmp_path, masses)
    real = deviated(nominal.with_compliance(lateral=True) if masses else nominal, 0)
    if masses:
        real = real.with_deviations(compliances(real, 5e-4))
    q = cc.poses.uniform(nominal, 60, seed=1)
    out = cc.compensate(real, q, nominal, frame="instrument")
    assert out.q.shape == q.shape and out.ok.mean() > 0.8, sorted(set(out.reason))
    distance, _ = misses(real, out.q, nominal, q)
    assert distance[out.ok].max() < 1e-6  # m, every tip
    assert np.median(misses(real, q, nominal, q)[0]) > 1e-3  # uncorrected: millimetres off
    for k in np.flatnonzero(~out.ok):
        assert out.reason[k] and np.array_equal(out.q[k], q[k])


def test_the_robot_frame_of_a_tree_is_the_best_fit_of_all_tips():
    nominal = two_arms()
    real = deviated(nominal, 1).with_deviations({"base_x": 4e-3, "base_rz": 0.01})
    q = cc.poses.uniform(nominal, 40, seed=2)
    out = cc.compensate(real, q, nominal)
    # the documented frame, by scipy's Kabsch over both tips of 200 poses (seed 0)
    qr = cc.poses.uniform(nominal, 200, seed=0)
    p, y = nominal.position(qr).reshape(-1, 3), real.position(qr).reshape(-1, 3)
    R, _ = Rotation.align_vectors(y - y.mean(axis=0), p - p.mean(axis=0))
    X = np.eye(4)
    X[:3, :3] = R.as_matrix()
    X[:3, 3] = y.mean(axis=0) - X[:3, :3] @ p.mean(axis=0)
    assert out.ok.mean() > 0.8
    assert misses(real, out.q, nominal, q, X)[0][out.ok].max() < 1e-6
    np.testing.assert_allclose(out.registration, X, atol=1e-9)


def test_orientation_is_matched_only_where_asked_and_possible():
    nominal = two_arms()
    real = deviated(nominal, 2)
    q = cc.poses.uniform(nominal, 5, seed=3)
    with pytest.raises(cc.CalibrationError, match=r"tip 'right_marker' .* moved by 4 joints"):
        cc.compensate(real, q, nominal, orientation=True)
    out = cc.compensate(real, q, nominal, frame="instrument", orientation=False)
    assert (out.orientation_error == 0).all()
    # a chain to one tip is not the tree's nominal
    with pytest.raises(cc.CalibrationError, match="same tips"):
        cc.compensate(real, q, cc.load_robot(EXAMPLE, tip_link=["left_marker"]))


def test_more_values_to_match_than_joints_are_refused(tmp_path):
    """The chest and both shoulder mounts turned into joints: six joints move each marker,
    so both orientations by default, 12 values for 10 joints: refused, positions work."""
    text = EXAMPLE.read_text()
    for name in ("chest_fixed", "right_mount", "left_mount"):
        text = text.replace(
            f'<joint name="{name}" type="fixed">',
            f'<joint name="{name}" type="revolute"><axis xyz="0 1 0"/>'
            '<limit lower="-1" upper="1" effort="1" velocity="1"/>',
        )
    (tmp_path / "ten.urdf").write_text(text)
    nominal = cc.load_robot(tmp_path / "ten.urdf", tip_link=TIPS)
    assert nominal.dof == 10
    real = deviated(nominal, 4)
    q = cc.poses.uniform(nominal, 20, seed=9)
    with pytest.raises(cc.CalibrationError, match="12 values to match and it has 10 joints"):
        cc.compensate(real, q, nominal)
    out = cc.compensate(real, q, nominal, frame="instrument", orientation=False)
    assert out.ok.mean() > 0.7 and misses(real, out.q, nominal, q)[0][out.ok].max() < 1e-6


def test_a_target_the_calibrated_tree_cannot_reach_is_reported(tmp_path):
    """The right marker at its farthest from the torso's axis (found here by scipy on the
    nominal tree): a calibrated tree whose right arm is 1 % shorter reaches less far
    whatever its joints (found by scipy too), so that pose cannot be corrected."""
    nominal = two_arms()
    right = [
        n
        for n in nominal.parameter_names
        if n.startswith("right_") and n[-2:] in (".x", ".y", ".z")
    ]
    real = nominal.with_parameters({n: 0.99 * nominal.parameters[n] for n in right})

    def farthest(robot):
        # the torso's yaw turns about that axis and the left arm moves the other marker:
        # the right arm's joints (2 to 4) alone set the distance
        def radius(x):
            return -np.linalg.norm(robot.position(np.r_[0.0, x, 0.0, 0.0, 0.0])[0, :2])

        starts = cc.poses.uniform(robot, 10, seed=4)[:, 1:4]
        best = min((minimize(radius, s, method="Nelder-Mead") for s in starts), key=lambda r: r.fun)
        return np.r_[0.0, best.x, 0.0, 0.0, 0.0], -best.fun

    q_far, r_nominal = farthest(nominal)
    r_real = farthest(real)[1]
    assert r_real < r_nominal - 1e-3  # out of the calibrated tree's reach by a millimetre
    q = np.vstack([q_far, cc.poses.uniform(nominal, 3, seed=6)])
    out = cc.compensate(real, q, nominal, frame="instrument")
    assert not out.ok[0] and out.ok[1:].all(), out.reason
    assert out.reason[0].startswith(("at a singularity", "not reached", "out of reach"))
    assert "tips up to" in out.reason[0] or out.reason[0].startswith("at a singularity")
    assert np.array_equal(out.q[0], q[0])
    assert out.position_error[0] > 0.5 * (r_nominal - r_real)


@pytest.mark.slow  # 12 s; the command-line test below runs the same robots on 8 poses
def test_the_elastic_humanoid_reaches_the_nominal_tips_with_controller_joints():
    """The study's humanoid: 18 model joints, a passive torso joint coupled to two others
    (17 controller joints), masses, joint and lateral compliance. Targets commanded on the
    nominal rigid robot; the true elastic robot sent the compensated joints puts both hands
    (11 joints each: position and orientation) where the nominal robot would."""
    from casecal.report.studies_elastic import humanoid, models, true_robot

    nominal = humanoid()
    true = true_robot(models()["joint + lateral compliance"], 0)
    rng = np.random.default_rng(7)
    lo, hi = nominal.limits.T
    mid = (lo + hi) / 2
    q = mid + 0.6 * (rng.uniform(lo, hi, size=(30, nominal.dof)) - mid)
    out = cc.compensate(true, q, nominal, frame="instrument")
    assert out.q.shape == (30, 17) and true.model_dof == 18
    assert out.ok.mean() > 0.8, sorted(set(out.reason))
    distance, turn = misses(true, out.q, nominal, q)
    assert distance[out.ok].max() < 1e-6 and turn[out.ok].max() < 1e-6
    assert np.median(misses(true, q, nominal, q)[0]) > 1e-3
    # the passive joint follows the coupling at the returned values
    model = true.model_joints(out.q)
    names = [j.name for j in true.joints]
    i4, i2, i3 = (names.index(f"torso_{k}") for k in (4, 2, 3))
    np.testing.assert_allclose(model[:, i4], -(model[:, i2] + model[:, i3]), atol=1e-15)


def test_the_command_line_compensates_a_tree(tmp_path, capsys):
    nominal = two_arms()
    real = deviated(nominal, 5)
    cc.save_robot(real, tmp_path / "real.toml")
    q = cc.poses.uniform(nominal, 10, seed=8)
    pd.DataFrame({f"q{i + 1}": q[:, i] for i in range(7)}).to_csv(tmp_path / "t.csv", index=False)
    argv = ["compensate", str(tmp_path / "real.toml"), str(tmp_path / "t.csv")]
    argv += ["--nominal", str(EXAMPLE), "--tip-link", ",".join(TIPS), "--frame", "instrument"]
    assert main([*argv, "-o", str(tmp_path / "out.csv")]) == 0, capsys.readouterr().err
    df = pd.read_csv(tmp_path / "out.csv")
    got = np.deg2rad(df[[f"q{i}_deg" for i in range(1, 8)]].to_numpy())
    ok = df.ok.to_numpy() == 1
    assert ok.mean() > 0.7
    assert misses(real, got, nominal, q)[0][ok].max() < 1e-6


def test_the_command_line_takes_the_coupled_elastic_humanoid(tmp_path, capsys):
    """Robot files of the true elastic humanoid and its nominal (couplings, compliance):
    17 controller joints in, 17 out, each tip where the nominal robot puts it."""
    from casecal.report.studies_elastic import humanoid, models, true_robot

    nominal = humanoid()
    true = true_robot(models()["joint + lateral compliance"], 0)
    cc.save_robot(true, tmp_path / "true.toml")
    cc.save_robot(nominal, tmp_path / "nominal.toml")
    lo, hi = nominal.limits.T
    q = (lo + hi) / 2 + 0.5 * (cc.poses.uniform(nominal, 8, seed=10) - (lo + hi) / 2)
    pd.DataFrame({f"q{i + 1}": q[:, i] for i in range(17)}).to_csv(tmp_path / "t.csv", index=False)
    argv = ["compensate", str(tmp_path / "true.toml"), str(tmp_path / "t.csv"), "--frame"]
    argv += ["instrument", "--nominal", str(tmp_path / "nominal.toml")]
    assert main([*argv, "-o", str(tmp_path / "out.csv")]) == 0, capsys.readouterr().err
    df = pd.read_csv(tmp_path / "out.csv")
    assert [c for c in df.columns if c.startswith("q")] == [f"q{i}_deg" for i in range(1, 18)]
    got, ok = np.deg2rad(df.filter(like="_deg").to_numpy()), df.ok.to_numpy() == 1
    assert ok.mean() > 0.7
    distance, turn = misses(true, got, nominal, q)
    assert distance[ok].max() < 1e-6 and turn[ok].max() < 1e-6
