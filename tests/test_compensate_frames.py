"""Issue 19, compensation: the real robot (the simulated truth) at the compensated joints
reaches the target in the frame the user states, whatever split of a blind combination
between base and joints the calibration chose; a row whose correction would be far larger
than the errors justify (near a singularity) is refused, with the joint and the numbers.

The robot frame's target is computed here apart from casecal: the nominal robot moved by
scipy's Kabsch fit of its tool points onto the true robot's over the documented poses
(200 uniform in the joint ranges, seed 0), and, independent of those poses, the reached
points must be a rigid image of the nominal ones.
"""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from random_robots import random_case
from scipy.spatial.transform import Rotation

import casecal as cc
from casecal.cli import main
from casecal.model.frames import rotation_vector

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
UR5E_ERRORS = {"theta1": 1e-3, "d1": 0.5e-3, "a2": 0.3e-3}  # rad, m (issue 19, case 2)
AMPLIFICATION = 30  # the documented limit: joint change × lever / pose difference


def kabsch(p, y):
    """(4, 4) rigid transform X minimising Σ |y - X p|² (scipy), and the RMS left, m."""
    R, _ = Rotation.align_vectors(y - y.mean(axis=0), p - p.mean(axis=0))
    X = np.eye(4)
    X[:3, :3] = R.as_matrix()
    X[:3, 3] = y.mean(axis=0) - X[:3, :3] @ p.mean(axis=0)
    rest = y - p @ X[:3, :3].T - X[:3, 3]
    return X, float(np.sqrt(np.mean(np.sum(rest**2, axis=1))))


def robot_frame(nominal, true):
    """The nominal robot's base frame placed where it best fits the true robot."""
    q = cc.poses.uniform(nominal, 200, seed=0)
    return kabsch(nominal.position(q), true.position(q))[0]


def misses(true, q, target):
    """Position (m) and orientation (rad) of the true tool at q against target (N, 4, 4)."""
    if len(q) == 0:  # no row was ok (an arm singular everywhere): nothing to miss
        return np.zeros(0), np.zeros(0)
    T = true.fk(q)
    rot = rotation_vector(target[:, :3, :3] @ np.transpose(T[:, :3, :3], (0, 2, 1)))
    return np.linalg.norm(T[:, :3, 3] - target[:, :3, 3], axis=1), np.linalg.norm(rot, axis=1)


def test_ur5e_reaches_the_target_however_the_calibration_split_the_base():
    """Case 2: θ1 = 1 mrad, d1 = 0.5 mm, a2 = 0.3 mm; "all" puts θ1/d1 into the base,
    "theta*,a*,d*" into the joints. On main (no frame): "all" left the real robot 1.04 mm
    from the instrument-frame target (1.17 mm uncompensated), "theta*,a*,d*" 1.02 mm from
    the robot-frame one, the two answers differed by up to 1.2° on joint 1, and
    position_error said 4e-16 m."""
    ur5e = cc.load_robot("ur5e")
    true = ur5e.with_deviations(UR5E_ERRORS)
    meas = cc.simulate(true, cc.poses.uniform(ur5e, 200, seed=0), noise=0.0, seed=1)
    q_t = cc.poses.uniform(ur5e, 100, seed=5)
    targets = {"robot": robot_frame(ur5e, true) @ ur5e.fk(q_t), "instrument": ur5e.fk(q_t)}
    answers = {}
    for parameters in ("all", "theta*,a*,d*"):
        cal = cc.identify(ur5e, meas, parameters)
        assert cal.success, cal.message
        for frame, target in targets.items():
            kwargs = {} if frame == "robot" else {"frame": "instrument"}  # robot: the default
            out = cc.compensate(cal.robot, q_t, nominal=ur5e, **kwargs)
            assert out.ok.mean() > 0.85, sorted(set(out.reason))
            ok = out.ok
            position, orientation = misses(true, out.q[ok], target[ok])
            assert position.max() < 1e-6, (parameters, frame, position.max())
            # the true robot has no error in the directions the positions cannot see
            assert orientation.max() < 1e-6, (parameters, frame, orientation.max())
            # and what casecal reports is what the real robot does
            assert np.abs(out.position_error[ok] - position).max() < 1e-6
            answers[parameters, frame] = out
        # base-like errors stay in the robot frame: the reached points are a rigid image of
        # the nominal robot's, whatever poses one aligns them over
        robot = answers[parameters, "robot"]
        _, rest = kabsch(ur5e.position(q_t[robot.ok]), true.position(robot.q[robot.ok]))
        assert rest < 1e-6
    for frame in targets:
        a, b = answers["all", frame], answers["theta*,a*,d*", frame]
        assert np.array_equal(a.ok, b.ok)
        assert np.abs(a.q[a.ok] - b.q[a.ok]).max() < 1e-9
    # uncompensated, the real robot misses the instrument-frame target by up to 1.2 mm
    assert misses(true, q_t, targets["instrument"])[0].max() > 0.7e-3


def test_ur5e_with_the_issues_noise_lands_at_the_noise_level():
    """Case 2 as reported: σ = 0.01 mm, "all". On main the real robot ended 1.04 mm off."""
    ur5e = cc.load_robot("ur5e")
    true = ur5e.with_deviations(UR5E_ERRORS)
    meas = cc.simulate(true, cc.poses.uniform(ur5e, 200, seed=0), noise=0.01e-3, seed=1)
    cal = cc.identify(ur5e, meas, "all")
    q_t = cc.poses.uniform(ur5e, 100, seed=5)
    out = cc.compensate(cal.robot, q_t, nominal=ur5e, frame="instrument")
    position, _ = misses(true, out.q[out.ok], ur5e.fk(q_t[out.ok]))
    assert out.ok.mean() > 0.85
    assert position.max() < 0.03e-3  # 3 σ; uncompensated 1.2 mm


def kr16_case(seed=0):
    nominal = cc.load_robot("kr16_2")
    rng = np.random.default_rng(seed)
    deviations = {
        n: rng.normal() * 1e-3
        for n in nominal.parameter_names
        if not n.startswith(("base", "tool"))
    }
    true = nominal.with_deviations(deviations)
    meas = cc.simulate(true, cc.poses.uniform(nominal, 100, seed=1), noise=0.0)
    cal = cc.identify(nominal, meas, "all")
    assert cal.success, cal.message
    return nominal, true, cal


def test_kr16_near_the_wrist_singularity_moves_no_joint_more_than_the_errors_justify():
    """Case 3: targets with q5 within ±0.02 rad of 0 and errors of about 1 mm and 1 mrad.
    On main, rows marked ok turned joints by up to 410° (96 of 170 beyond the bound). A
    row is justified to turn a joint by at most 30 × (position difference / L +
    orientation difference), L = half the reach (a radian counted as L metres), and turns
    nothing by 10° or more."""
    nominal, true, cal = kr16_case()
    rng = np.random.default_rng(3)
    q_t = cc.poses.uniform(nominal, 200, seed=2)
    q_t[:, 4] = rng.uniform(-0.02, 0.02, len(q_t))
    X = robot_frame(nominal, true)
    out = cc.compensate(cal.robot, q_t, nominal=nominal)
    ok = out.ok
    assert ok.any()
    dp, dphi = misses(true, q_t, X @ nominal.fk(q_t))  # what the correction must undo
    justified = AMPLIFICATION * (dp / (0.5 * nominal.reach) + dphi)
    moved = np.abs(out.q - q_t).max(axis=1)
    assert np.all(moved[ok] <= justified[ok]), (moved[ok] / justified[ok]).max()
    assert np.rad2deg(moved[ok]).max() < 10
    position, _ = misses(true, out.q[ok], X @ nominal.fk(q_t[ok]))
    assert position.max() < 1e-6
    refused = [out.reason[k] for k in np.flatnonzero(~ok)]
    assert all("singularity" in r or "limits of joint" in r for r in refused), refused
    # the same targets away from the singularity are corrected
    q_t[:, 4] = rng.choice([-1, 1], len(q_t)) * rng.uniform(0.5, 1.5, len(q_t))
    assert cc.compensate(cal.robot, q_t, nominal=nominal).ok.mean() > 0.85


def test_the_readme_kr16_row_at_the_wrist_singularity_is_refused_with_numbers(tmp_path, capsys):
    """The README's kr16 commands with target 10,100,-20,0,0,0 deg: on main, ok with
    q4 +41.3° and q6 −41.3°."""
    urdf = str(EXAMPLES / "kr16_2.urdf")
    session, calibrated = tmp_path / "session.csv", tmp_path / "kr16_calibrated.toml"
    simulate = ["simulate", urdf, "--poses", "60", "--schedule", "uniform", "--seed", "2"]
    deviations = ["--deviations", str(EXAMPLES / "kr16_deviations.toml")]
    assert main([*simulate, *deviations, "--noise", "0.02mm", "-o", str(session)]) == 0
    assert main(["identify", urdf, str(session), "--parameters", "all", "-o", str(calibrated)]) == 0
    targets = tmp_path / "targets.csv"
    targets.write_text("q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n10,100,-20,0,0,0\n")
    out = tmp_path / "out.csv"
    argv = ["compensate", str(calibrated), str(targets), "--nominal", urdf, "-o", str(out)]
    assert main(argv) == 0
    assert "1 could not be corrected" in capsys.readouterr().out
    row = pd.read_csv(out).iloc[0]
    sent = row[[f"q{i}_deg" for i in range(1, 7)]].to_numpy(float)
    moved = np.abs(sent - [10, 100, -20, 0, 0, 0])
    if row.ok:
        assert moved.max() < 1.0
    else:
        assert moved.max() == 0  # a refused row keeps its target
        assert "near a singularity (axes of joints 4 and 6" in row.reason
        turned = re.search(r"turn joint ([46]) by (-?[\d.]+)°", row.reason)
        # a wrist turn of several degrees for a sub-millimetre, milliradian pose difference:
        # the refusal bound (30x the pose difference over the levers) is about 2.3° here
        assert turned and abs(float(turned.group(2))) > 5, row.reason


# --- property: random DH and URDF arms, several parameter sets --------------------------

SETS = {
    # parameter set: which deviations the true robot has (families, None: all)
    "all": None,
    "theta*,a*,d*,base_*": ("theta", "a", "d", "base"),
}


def scaled_condition(robot, q, rows):
    """Condition number of the joint Jacobian (finite differences of fk, not casecal's
    Jacobian) with each joint's column divided by its lever (a radian = half the reach)."""
    length, h = 0.5 * robot.reach, 1e-7
    out = []
    for x in q:
        T0, columns = robot.fk(x), []
        for i in range(len(x)):
            T1 = robot.fk(x + h * np.eye(len(x))[i])
            W = (T1[:3, :3] @ T0[:3, :3].T - np.eye(3)) / h
            w = length * np.array([W[2, 1], W[0, 2], W[1, 0]])
            columns.append(np.r_[(T1[:3, 3] - T0[:3, 3]) / h, w])
        A = np.array(columns).T
        s = np.linalg.svd((A / np.linalg.norm(A, axis=0))[rows], compute_uv=False)
        out.append(s[0] / max(s[-1], 1e-300))
    return np.array(out)


def check_case(nominal, true, q_fit, q_t, parameters):
    """Noise-free identification of `true` with `parameters`, then compensation in both
    frames; returns the robot-frame answer (None when identification refused)."""
    meas = cc.simulate(true, q_fit, noise=0.0, seed=7)
    cal = cc.identify(nominal, meas, parameters)
    if not cal.success:
        return None
    out = cc.compensate(cal.robot, q_t, nominal=nominal)
    target = robot_frame(nominal, true) @ nominal.fk(q_t)
    position, _ = misses(true, out.q[out.ok], target[out.ok])
    assert position.max(initial=0) < 1e-6, (parameters, position.max())
    # a user who measured the base: the nominal robot with the true base, instrument frame
    base = {n: v for n, v in true.parameters.items() if n.startswith("base_")}
    measured = nominal.with_parameters(base)
    inst = cc.compensate(cal.robot, q_t, nominal=measured, frame="instrument")
    position, _ = misses(true, inst.q[inst.ok], measured.fk(q_t)[inst.ok])
    assert position.max(initial=0) < 1e-6, (parameters, position.max())
    for k in np.flatnonzero(~out.ok):
        assert out.reason[k] and np.array_equal(out.q[k], q_t[k])
    return out


def truth_for(case, families):
    nominal = case.nominal
    full = {n: case.true.parameters[n] - nominal.parameters[n] for n in nominal.parameter_names}
    if families is None:
        return case.true
    kept = {n: v for n, v in full.items() if re.match(r"[a-z]+", n).group(0) in families}
    return nominal.with_deviations(kept)


def check_dh(seed):
    case = random_case(seed, noisy=False)
    q_t = case.q_new[:100]
    rows = slice(None) if case.nominal.dof >= 6 else slice(0, 3)
    away = scaled_condition(case.nominal, q_t, rows) < 10
    answers = {}
    for parameters, families in SETS.items():
        true = truth_for(case, families)
        answers[parameters] = out = check_case(case.nominal, true, case.q_fit, q_t, parameters)
        if out is not None and away.sum() >= 5:
            assert out.ok[away].mean() >= 0.85, sorted(set(np.array(out.reason)[away]))
    # the θ/a/d truth fitted with "all" (the fit chooses the blind splits) lands alike
    tad = truth_for(case, SETS["theta*,a*,d*,base_*"])
    both = answers["theta*,a*,d*,base_*"], check_case(case.nominal, tad, case.q_fit, q_t, "all")
    if None not in both:
        ok = both[0].ok & both[1].ok
        assert ok.mean() > 0.5 or not away.any()
        reached = tad.position(both[0].q) - tad.position(both[1].q)
        assert np.abs(reached[ok]).max(initial=0) < 1e-6
        if case.nominal.dof < 6:
            # only the position is matched: the same joints. With six or more joints the
            # tool's orientation is matched too, and from positions alone it may be blind
            # (a last joint and a tool offset turned against each other): two fits may
            # then orient the tool differently, and their joints differ (documented)
            assert np.abs(both[0].q[ok] - both[1].q[ok]).max(initial=0) < 1e-8
    return answers


def check_urdf(seed, tmp_path):
    case = random_case(seed, noisy=False)
    base = {n: v for n, v in case.true.parameters.items() if n.startswith("base_")}
    cc.save_robot(case.nominal, tmp_path / "nominal.urdf")
    in_base = dataclasses.replace(case.true, base=cc.Frame(), auto_beta=False)
    cc.save_robot(in_base, tmp_path / "true.urdf")
    nominal = cc.load_robot(tmp_path / "nominal.urdf")
    true = cc.load_robot(tmp_path / "true.urdf").with_parameters(base)
    q_t = case.q_new[:100]
    for parameters in ("all", "*.x,*.y,*.z,*.roll,*.pitch,*.yaw,base_*"):
        check_case(nominal, true, case.q_fit, q_t, parameters)


@pytest.mark.parametrize("seed", [9, 12])
def test_random_dh_arms_reach_the_target_on_every_ok_row(seed):
    """5R position-only and PPRRRP full-pose arms, far and turned tracker."""
    assert all(out is not None for out in check_dh(seed).values())


def test_a_random_urdf_arm_reaches_the_target_on_every_ok_row(tmp_path):
    check_urdf(12, tmp_path)


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(30))
def test_random_dh_arms_sweep(seed):
    check_dh(seed)


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(10))
def test_random_urdf_arms_sweep(seed, tmp_path):
    check_urdf(seed, tmp_path)


# --- frames that do not fit -----------------------------------------------------------------


def test_an_instrument_frame_without_the_measured_base_is_refused_in_words(tmp_path, capsys):
    """A calibration measured by a tracker 2 m away: the instrument frame needs the
    nominal robot's base where the tracker saw it; the robot frame needs nothing."""
    nominal = cc.load_robot("puma560")
    true = nominal.with_deviations({"a2": 3e-4, "base_x": 2.0, "base_rz": 0.5})
    meas = cc.simulate(true, cc.poses.uniform(nominal, 60, seed=0), noise=0.0)
    cal = cc.identify(nominal, meas, "all")
    q_t = cc.poses.uniform(nominal, 20, seed=1)
    with pytest.raises(cc.CalibrationError, match="--frame robot") as info:
        cc.compensate(cal.robot, q_t, nominal=nominal, frame="instrument")
    assert "frame='instrument'" in str(info.value) and "base frame" in str(info.value)
    assert cc.compensate(cal.robot, q_t, nominal=nominal).ok.mean() > 0.8
    with pytest.raises(cc.CalibrationError, match="unknown compensation frame"):
        cc.compensate(cal.robot, q_t, nominal=nominal, frame="world")
    # another robot as the nominal: not calibration errors
    with pytest.raises(cc.CalibrationError, match="mm apart"):
        cc.compensate(cal.robot, q_t, nominal=cc.load_robot("kr15_2"))
    cc.save_robot(cal.robot, tmp_path / "cal.toml")
    cc.save_robot(nominal, tmp_path / "nominal.toml")
    pd.DataFrame({f"q{i}": q_t[:, i - 1] for i in range(1, 7)}).to_csv(
        tmp_path / "t.csv", index=False
    )
    argv = ["compensate", str(tmp_path / "cal.toml"), str(tmp_path / "t.csv")]
    argv += ["--nominal", str(tmp_path / "nominal.toml"), "-o", str(tmp_path / "o.csv")]
    assert main([*argv, "--frame", "instrument"]) == 2
    assert "--frame robot" in capsys.readouterr().err
    assert main(argv) == 0


def test_position_only_compensation_does_not_depend_on_a_blind_tool_orientation(tmp_path):
    """From positions alone a six-axis arm's tool orientation may be blind: matching the
    whole pose then corrects an orientation nobody measured. With orientation=False the
    position is matched with the least joint motion, and two calibrations that split the
    blind combinations differently ("all" and "theta*,a*,d*") return the same joints."""
    ur5e = cc.load_robot("ur5e")
    true = ur5e.with_deviations(UR5E_ERRORS)
    meas = cc.simulate(true, cc.poses.uniform(ur5e, 200, seed=0), noise=0.0, seed=1)
    q_t = cc.poses.uniform(ur5e, 60, seed=5)
    answers = []
    for parameters in ("all", "theta*,a*,d*"):
        cal = cc.identify(ur5e, meas, parameters.split(",") if "," in parameters else parameters)
        out = cc.compensate(cal.robot, q_t, nominal=ur5e, frame="instrument", orientation=False)
        assert out.ok.mean() > 0.85
        assert not out.orientation_error.any()
        reached = true.fk(out.q[out.ok])[:, :3, 3] - ur5e.fk(q_t[out.ok])[:, :3, 3]
        assert np.abs(reached).max() < 1e-6, parameters
        answers.append(out)
    both = answers[0].ok & answers[1].ok
    assert both.mean() > 0.85
    assert np.abs(answers[0].q[both] - answers[1].q[both]).max() < 1e-9
    with pytest.raises(cc.CalibrationError, match="too few"):
        rr = cc.load_robot("rr")
        cc.compensate(rr, np.zeros((1, 2)), nominal=rr, orientation=True)


def test_the_command_line_compensates_positions_only(tmp_path, capsys):
    ur5e = cc.load_robot("ur5e")
    true = ur5e.with_deviations(UR5E_ERRORS)
    meas = cc.simulate(true, cc.poses.uniform(ur5e, 200, seed=0), noise=0.0, seed=1)
    calibrated = tmp_path / "cal.toml"
    cc.save_robot(cc.identify(ur5e, meas, "all").robot, calibrated)
    targets = tmp_path / "t.csv"
    targets.write_text("q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n10,-80,60,-40,50,20\n")
    out = tmp_path / "o.csv"
    argv = ["compensate", str(calibrated), str(targets), "--nominal", "ur5e", "-o", str(out)]
    assert main([*argv, "--position-only"]) == 0
    row = pd.read_csv(out).iloc[0]
    assert row.ok and row.orientation_error_mrad == 0
