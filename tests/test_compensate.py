"""Compensated joint targets (issue 11): the calibrated robot sent the corrected values
reaches where the nominal robot would at the targets (in the robot's base frame, the
nominal robot placed where it best fits the real one, or in the instrument's frame).
Issue 19's cases are in test_compensate_frames.py."""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation

import casecal as cc
from casecal.cli import main
from casecal.model.frames import rotation_vector


def real_and_nominal(name, seed=0):
    nominal = cc.load_robot(name)
    rng = np.random.default_rng(seed)
    deviations = {
        n: rng.normal() * 1e-3 for n in nominal.parameter_names if not n.startswith("base")
    }
    return nominal.with_deviations(deviations), nominal


def best_fit(nominal, real):
    """The rigid transform (4, 4) taking the nominal robot's tool points onto the real
    one's over 200 poses uniform in the joint ranges (seed 0), by scipy's Kabsch: what
    the robot frame is documented to be, computed apart from casecal."""
    q = cc.poses.uniform(nominal, 200, seed=0)
    p, y = nominal.position(q), real.position(q)
    R, _ = Rotation.align_vectors(y - y.mean(axis=0), p - p.mean(axis=0))
    X = np.eye(4)
    X[:3, :3] = R.as_matrix()
    X[:3, 3] = y.mean(axis=0) - X[:3, :3] @ p.mean(axis=0)
    return X


@pytest.mark.parametrize("frame", ["robot", "instrument"])
@pytest.mark.parametrize("name", ["puma560", "kr15_2", "ur5e", "irb120"])
def test_six_axis_arms_reach_the_nominal_pose(name, frame):
    real, nominal = real_and_nominal(name)
    q = cc.poses.uniform(nominal, 300, seed=1)
    out = cc.compensate(real, q, nominal, frame=frame)
    assert out.ok.mean() > 0.85, sorted(set(out.reason))
    # the bases are both the identity: the instrument's frame is the nominal base frame
    X = best_fit(nominal, real) if frame == "robot" else np.eye(4)
    want, got = X @ nominal.fk(q[out.ok]), real.fk(out.q[out.ok])
    assert np.abs(got[:, :3, 3] - want[:, :3, 3]).max() < 1e-9  # m
    rot = rotation_vector(want[:, :3, :3] @ np.transpose(got[:, :3, :3], (0, 2, 1)))
    assert np.abs(rot).max() < 1e-9  # rad
    # without correction the real robot misses by about the deviations' effect
    assert np.abs(real.fk(q)[:, :3, 3] - (X @ nominal.fk(q))[:, :3, 3]).max() > 1e-4
    # a row that cannot be corrected says why and keeps its target
    for k in np.flatnonzero(~out.ok):
        assert out.reason[k] and np.array_equal(out.q[k], q[k])


def test_fewer_than_six_joints_match_the_position():
    real, nominal = real_and_nominal("scorbot")
    q = cc.poses.uniform(nominal, 200, seed=2)
    out = cc.compensate(real, q, nominal)
    assert out.ok.mean() > 0.9
    want = best_fit(nominal, real) @ nominal.fk(q[out.ok])
    assert np.abs(real.position(out.q[out.ok]) - want[:, :3, 3]).max() < 1e-9


def test_a_target_out_of_the_real_robots_reach_is_flagged():
    """A planar RR arm at full stretch: the real one, 1 mm shorter, cannot get there."""
    nominal = cc.load_robot("rr")
    real = nominal.with_deviations({"a2": -1e-3})
    q = np.array([[0.3, 0.0], [0.3, 0.5]])
    out = cc.compensate(real, q, nominal)
    assert list(out.ok) == [False, True]
    assert out.reason[0].startswith(("at a singularity", "not reached", "out of reach"))
    assert out.position_error[0] > 0.5e-3 and out.position_error[1] < 1e-12


def test_the_nominal_defaults_to_calibrated_from_and_the_command_line(tmp_path, capsys):
    real, nominal = real_and_nominal("puma560")
    calibrated = dataclasses.replace(real, calibrated_from="puma560", auto_beta=False)
    cc.save_robot(calibrated, tmp_path / "cal.toml")
    q = cc.poses.uniform(nominal, 20, seed=4)
    pd.DataFrame({f"q{i + 1}_deg": np.rad2deg(q[:, i]) for i in range(6)}).to_csv(
        tmp_path / "targets.csv", index=False
    )
    argv = ["compensate", str(tmp_path / "cal.toml"), str(tmp_path / "targets.csv")]
    assert main([*argv, "-o", str(tmp_path / "corrected.csv")]) == 0
    assert "wrote 20 corrected targets" in capsys.readouterr().out
    df = pd.read_csv(tmp_path / "corrected.csv")
    api = cc.compensate(cc.load_robot(tmp_path / "cal.toml"), q)
    np.testing.assert_allclose(
        np.deg2rad(df[[f"q{i}_deg" for i in range(1, 7)]]), api.q, atol=1e-12
    )
    assert (df.ok == api.ok.astype(int)).all()
    with pytest.raises(cc.CalibrationError, match="nominal"):
        cc.compensate(real, q)


def test_without_a_nominal_the_message_names_the_flag_and_the_keyword(tmp_path, capsys):
    """Issue 19, case 13: a shell user reads --nominal, a Python user nominal=."""
    real, nominal = real_and_nominal("puma560")
    with pytest.raises(cc.CalibrationError) as info:
        cc.compensate(real, cc.poses.uniform(nominal, 3, seed=0))
    assert "--nominal" in str(info.value) and "nominal=" in str(info.value)
    cc.save_robot(real, tmp_path / "real.toml")
    pd.DataFrame({f"q{i}": [0.1] for i in range(1, 7)}).to_csv(tmp_path / "t.csv", index=False)
    argv = ["compensate", str(tmp_path / "real.toml"), str(tmp_path / "t.csv")]
    assert main([*argv, "-o", str(tmp_path / "out.csv")]) == 2
    assert "--nominal" in capsys.readouterr().err
