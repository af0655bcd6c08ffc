"""The UR kinematics file (issue 11): written from a DH or a URDF robot, read back as the
chain it describes."""

from __future__ import annotations

import numpy as np
import pytest

import casecal as cc

EXAMPLE = """\
kinematics:
  shoulder:
    x: 0
    y: 0
    z: 0.1627
    roll: 0
    pitch: 0
    yaw: 1e-6
  upper_arm: {upper_arm}
  forearm:
    x: -0.4252
    y: 0
    z: 0
    roll: 0.001
    pitch: 0.0008
    yaw: 0
  wrist_1:
    x: -0.3926
    y: -0.0009
    z: 0.1335
    roll: 0.0065
    pitch: -0.0019
    yaw: 0
  wrist_2:
    x: 0
    y: -0.0999
    z: 0
    roll: 1.5703
    pitch: 0
    yaw: 0
  wrist_3:
    x: 0.0001
    y: 0.0995
    z: 0.0002
    roll: 1.5731
    pitch: 3.141592653589793
    yaw: 3.1415924
  hash: calib_12345  # a comment
"""
UPPER_ARM = "\n    x: 0.0002\n    y: 0\n    z: 0\n    roll: 1.5703\n    pitch: 0\n    yaw: 0"


def calibrated_ur5e(with_tool_side=False):
    ur = cc.load_robot("ur5e")
    rng = np.random.default_rng(0)
    skip = ("base", "tool") if with_tool_side else ("base", "tool", "a6", "alpha6")
    return ur.with_deviations(
        {n: rng.normal() * 1e-3 for n in ur.parameter_names if not n.startswith(skip)}
    )


def test_a_dh_robot_round_trips(tmp_path):
    q = cc.poses.uniform(cc.load_robot("ur5e"), 60, seed=1)
    for robot in (cc.load_robot("ur5e"), calibrated_ur5e()):
        assert cc.save_robot(robot, tmp_path / "k.yaml") == []
        back = cc.load_robot(tmp_path / "k.yaml")
        assert back.dof == 6 and back.parameter_names[0] == "shoulder_pan_joint.x"
        assert np.abs(back.fk(q) - robot.fk(q)).max() < 1e-12


def test_what_the_file_cannot_hold_is_said(tmp_path):
    with pytest.warns(cc.CalibrationWarning, match="a6 = .* mm and alpha6 = .*° have no place"):
        notes = cc.save_robot(calibrated_ur5e(with_tool_side=True), tmp_path / "k.yaml")
    assert notes[0].startswith("this file loses up to") and "TCP" in notes[0]
    moved = cc.load_robot("ur5e").with_deviations({"base_x": 2.0})
    assert any("base frame" in n for n in cc.save_robot(moved, tmp_path / "b.yaml"))
    with pytest.raises(cc.CalibrationError, match="six revolute joints"):
        cc.save_robot(cc.load_robot("puma560_craig"), tmp_path / "p.yaml")


def test_a_ur_urdf_writes_the_file_its_description_package_reads(tmp_path):
    (tmp_path / "calib.yaml").write_text(EXAMPLE.format(upper_arm=UPPER_ARM))
    from_file = cc.load_robot(tmp_path / "calib.yaml")
    cc.save_robot(from_file, tmp_path / "ur.urdf")
    urdf = cc.load_robot(tmp_path / "ur.urdf")
    q = cc.poses.uniform(urdf, 40, seed=2)
    assert np.abs(urdf.fk(q) - from_file.fk(q)).max() < 1e-12
    moved = urdf.with_deviations({"elbow_joint.offset": 1e-3, "wrist_1_joint.y": 1e-4})
    notes = cc.save_robot(moved, tmp_path / "again.yaml")
    assert any("offset" in n for n in notes)
    assert np.abs(cc.load_robot(tmp_path / "again.yaml").fk(q) - moved.fk(q)).max() < 1e-12


def test_a_malformed_file_is_one_clear_error(tmp_path):
    (tmp_path / "bad.yaml").write_text(EXAMPLE.format(upper_arm="\n    x: 0"))
    with pytest.raises(cc.CalibrationError, match="upper_arm misses y, z, roll, pitch, yaw"):
        cc.load_robot(tmp_path / "bad.yaml")
    (tmp_path / "bad2.yaml").write_text(EXAMPLE.format(upper_arm=UPPER_ARM).replace("0.0995", "?"))
    with pytest.raises(cc.CalibrationError, match="is not a number"):
        cc.load_robot(tmp_path / "bad2.yaml")
