"""Robots in as URDF and out as URDF (issue 11), checked against roboticstoolbox-python's
URDF reader and the URDFs its data package ships."""

from __future__ import annotations

import difflib
import re
from pathlib import Path

import numpy as np
import pytest

import casecal as cc
from casecal.cli import main
from casecal.model.urdf import transform

rtbdata = pytest.importorskip("rtbdata")
rtb = pytest.importorskip("roboticstoolbox")
URDFS = sorted((Path(rtbdata.__file__).parent / "xacro").glob("*/**/*.urdf"))
KR16 = next(p for p in URDFS if p.name == "kr16_2.urdf")


def oracle(path: Path):
    """roboticstoolbox's forward kinematics of a URDF file (meshes dropped: they point to
    ROS packages that are not installed, and do not move anything)."""
    from roboticstoolbox.models.URDF.URDFRobot import _parse_urdf

    text = re.sub(r"<(visual|collision)\b.*?</\1>", "", path.read_text(), flags=re.S)
    links, name = _parse_urdf(text, source=str(path))
    robot = rtb.Robot(links, name=name)
    return lambda q, tip: np.array([robot.fkine(row, end=tip).A for row in q])


def tip_of(robot) -> str:
    return robot.urdf.tip_link if robot.urdf is not None else "tool0"


@pytest.mark.parametrize("path", URDFS, ids=lambda p: p.name)
def test_forward_kinematics_agrees_with_roboticstoolbox(path):
    robot = cc.load_robot(path)
    q = cc.poses.uniform(robot, 40, seed=0)
    assert np.abs(oracle(path)(q, tip_of(robot)) - robot.fk(q)).max() < 1e-12


def test_names_and_patterns():
    robot = cc.load_robot(KR16)
    assert robot.dof == 6 and robot.convention == "urdf"
    assert robot.urdf.tip_link == "tool0"  # the one chain, then its fixed links
    offsets = [n for n in robot.parameter_names if n.endswith(".offset")]
    _, names = robot.position_jacobian(np.zeros(6), "*.offset")
    assert names == offsets == [f"joint_a{i}.offset" for i in range(1, 7)]
    _, names = robot.position_jacobian(np.zeros(6), "base_*")
    assert names == [f"base_{a}" for a in ("x", "y", "z", "rx", "ry", "rz")]


def _session(robot, n, seed, orientation=False):
    rng = np.random.default_rng(seed)
    deviations = {
        n: rng.normal() * 1e-3  # about 1 mm and 1 mrad on every joint origin
        for n in robot.parameter_names
        if "." in n
    }
    deviations.update(base_x=2.1, base_y=-0.8, base_z=0.3, base_rz=2.2)  # a tracker 2 m away
    true = robot.with_deviations(deviations)
    q = cc.poses.uniform(robot, n, seed=seed + 1)
    extra = {"orientation_noise": 2e-5} if orientation else {}
    return true, cc.simulate(true, q, noise=2e-5, seed=seed + 2, **extra)


@pytest.mark.parametrize("orientation, count", [(False, 27), (True, 30)])
def test_every_joint_origin_with_a_base_and_a_marker_reaches_the_noise(orientation, count):
    """The redundant URDF set (7 per joint) reduces to the DH count by itself: 4 per
    revolute joint and 6 for the base, less the 3 tool rotations positions cannot see."""
    robot = cc.load_robot(KR16).with_points([[0.05, 0.02, 0.03]])
    true, meas = _session(robot, 80, seed=0, orientation=orientation)
    cal = cc.identify(robot, meas, "all")
    assert cal.success, cal.message
    assert len(cal.estimated) == count
    q = cc.poses.uniform(robot, 300, seed=9)
    err = cal.robot.measured_points(q) - true.measured_points(q)
    held_out = np.sqrt(np.mean(np.sum(err**2, axis=-1)))
    assert held_out < 0.02e-3 * np.sqrt(3)  # m: below one measurement's noise


def test_the_calibrated_urdf_changes_only_the_origins_and_reads_back(tmp_path):
    robot = cc.load_robot(KR16)
    _, meas = _session(robot, 60, seed=3)
    cal = cc.identify(robot, meas, "all")
    assert cal.success
    notes = cc.save_robot(cal.robot, tmp_path / "calibrated.urdf")
    assert any("base frame" in n for n in notes)
    q = cc.poses.uniform(robot, 50, seed=4)
    theirs = oracle(tmp_path / "calibrated.urdf")(q, "tool0")
    # the base frame (the tracker's) stays out of the URDF: compare in the base link's frame
    base = transform(cal.robot.base.xyz, cal.robot.base.rpy)
    ours = np.linalg.inv(base)[None] @ cal.robot.fk(q)
    assert np.abs(theirs[:, :3, 3] - ours[:, :3, 3]).max() < 1e-9
    before = KR16.read_text().splitlines()
    after = (tmp_path / "calibrated.urdf").read_text().splitlines()
    changed = [
        line
        for line in difflib.unified_diff(before, after, lineterm="", n=0)
        if line[:1] in "+-" and line[:3] not in ("+++", "---")
    ]
    assert len(before) == len(after)
    assert changed and all("<origin" in line for line in changed)


@pytest.mark.parametrize("name", ["puma560", "kr15_2", "scorbot", "irb120", "rx90b"])
def test_a_dh_robot_exports_the_same_chain(tmp_path, name):
    robot = cc.load_robot(name)
    robot = robot.with_deviations({n: 1e-3 for n in robot.parameter_names})
    cc.save_robot(robot, tmp_path / "r.urdf")
    q = cc.poses.uniform(robot, 40, seed=1)
    assert np.abs(oracle(tmp_path / "r.urdf")(q, "tool0") - robot.fk(q)).max() < 1e-12
    assert np.abs(cc.load_robot(tmp_path / "r.urdf").fk(q) - robot.fk(q)).max() < 1e-12


def test_dh_and_its_urdf_calibrate_alike(tmp_path):
    dh = cc.load_robot("puma560").with_points([[0.05, 0.0, 0.1]])
    cc.save_robot(dh, tmp_path / "puma.urdf")
    urdf = cc.load_robot(tmp_path / "puma.urdf").with_points([[0.05, 0.0, 0.1]])
    rng = np.random.default_rng(5)
    true = dh.with_deviations({n: rng.normal() * 5e-4 for n in dh.parameter_names if n[0] in "tad"})
    q = cc.poses.uniform(dh, 60, seed=6)
    meas = cc.simulate(true, q, noise=2e-5, seed=7)
    q_new = cc.poses.uniform(dh, 300, seed=8)
    errors = []
    for nominal in (dh, urdf):
        cal = cc.identify(nominal, meas, "all")
        assert cal.success, cal.message
        err = cal.robot.measured_points(q_new) - true.measured_points(q_new)
        errors.append(np.sqrt(np.mean(np.sum(err**2, axis=-1))))
    assert errors[1] == pytest.approx(errors[0], rel=0.05)


def test_a_tree_without_a_tip_names_the_candidates(tmp_path):
    text = """<robot name="y">
      <link name="b"/><link name="l"/><link name="r"/>
      <joint name="jl" type="continuous"><parent link="b"/><child link="l"/></joint>
      <joint name="jr" type="continuous"><parent link="b"/><child link="r"/></joint>
    </robot>"""
    (tmp_path / "y.urdf").write_text(text)
    with pytest.raises(cc.CalibrationError, match="tip_link= one of l, r"):
        cc.load_robot(tmp_path / "y.urdf")
    assert cc.load_robot(tmp_path / "y.urdf", tip_link="r").parameter_names[0] == "jr.x"
    assert main(["show", str(tmp_path / "y.urdf")]) == 2
    assert main(["show", str(tmp_path / "y.urdf"), "--tip-link", "r"]) == 0


def test_the_command_line_reads_and_writes_urdf(tmp_path, capsys):
    assert main(["show", str(KR16)]) == 0
    assert "joint_a4" in capsys.readouterr().out
    robot = cc.load_robot(KR16).with_points([[0.05, 0.02, 0.03]])
    _, meas = _session(robot, 60, seed=11)
    cc.write_csv(tmp_path / "m.csv", meas, robot)
    cc.save_robot(robot, tmp_path / "kr16.toml")
    out = tmp_path / "calibrated.urdf"
    argv = ["identify", str(tmp_path / "kr16.toml"), str(tmp_path / "m.csv"), "-o", str(out)]
    assert main([*argv, "--parameters", "all"]) == 0
    assert cc.load_robot(out).dof == 6
    # a format that cannot hold this robot is refused before the fit, not after it
    capsys.readouterr()
    yaml = ["identify", str(tmp_path / "kr16.toml"), str(tmp_path / "m.csv"), "-o", "k.yaml"]
    assert main(yaml) == 2
    captured = capsys.readouterr()
    assert "UR kinematics file needs" in captured.err and "Answer audit" not in captured.out


def test_joint_offsets_fold_into_the_origins(tmp_path):
    robot = cc.load_robot(KR16)
    moved = robot.with_deviations({f"joint_a{i}.offset": 0.01 * i for i in range(1, 7)})
    notes = cc.save_robot(moved, tmp_path / "offsets.urdf")
    assert any("no joint offset" in n for n in notes)
    q = cc.poses.uniform(robot, 30, seed=2)
    assert np.abs(oracle(tmp_path / "offsets.urdf")(q, "tool0") - moved.fk(q)).max() < 1e-12


def test_a_xacro_file_expands_to_the_same_robot(tmp_path):
    pytest.importorskip("xacro")
    joint = """
      <xacro:macro name="arm_joint" params="n parent child z">
        <joint name="${n}" type="revolute">
          <parent link="${parent}"/><child link="${child}"/>
          <origin xyz="0.1 0 ${z}" rpy="0 ${pi/2} 0"/><axis xyz="0 0 1"/>
          <limit lower="-3" upper="3" effort="1" velocity="1"/>
        </joint>
      </xacro:macro>"""
    text = f"""<robot name="two" xmlns:xacro="http://www.ros.org/wiki/xacro">{joint}
      <link name="a"/><link name="b"/><link name="c"/>
      <xacro:arm_joint n="j1" parent="a" child="b" z="0.3"/>
      <xacro:arm_joint n="j2" parent="b" child="c" z="${{0.3 * 2}}"/>
    </robot>"""
    (tmp_path / "two.urdf.xacro").write_text(text)
    robot = cc.load_robot(tmp_path / "two.urdf.xacro")
    assert robot.parameter_names[:2] == ("j1.x", "j1.y")
    assert robot.joints[1].xyz == (0.1, 0.0, 0.6) and robot.joints[1].rpy[1] == np.pi / 2
    (tmp_path / "find.xacro").write_text(
        '<robot name="f" xmlns:xacro="http://www.ros.org/wiki/xacro">'
        '<xacro:include filename="$(find nowhere)/x.xacro"/></robot>'
    )
    with pytest.raises(cc.CalibrationError, match=r"packages=\{name: folder\}"):
        cc.load_robot(tmp_path / "find.xacro")


def test_the_panda_from_xacro_agrees_with_roboticstoolbox():
    """rtbdata ships the Panda as xacro that finds ROS packages; casecal expands it with
    the package folders named, as roboticstoolbox does for its own model."""
    pytest.importorskip("xacrodoc")
    root = Path(rtbdata.__file__).parent / "xacro"
    folders = {d.name: str(d) for d in root.iterdir() if d.is_dir()}
    path = root / "qut_frankie_description" / "robots" / "panda_arm_hand.urdf.xacro"
    robot = cc.load_robot(path, packages=folders, tip_link="panda_hand")
    assert robot.dof == 7
    theirs = rtb.models.URDF.Panda()
    q = cc.poses.uniform(robot, 30, seed=0)
    reference = np.array([theirs.fkine(row, end="panda_hand").A for row in q])
    assert np.abs(reference - robot.fk(q)).max() < 1e-12


def _three_joints(mimic: str) -> str:
    limit = '<limit lower="-2" upper="2" effort="1" velocity="1"/>'
    return f"""<robot name="par">
      <link name="b"/><link name="l1"/><link name="l2"/><link name="l3"/><link name="tip"/>
      <joint name="j1" type="revolute"><parent link="b"/><child link="l1"/>
        <origin xyz="0 0 0.4"/><axis xyz="0 1 0"/>{limit}</joint>
      <joint name="m1" type="revolute"><parent link="l1"/><child link="l2"/>
        <origin xyz="0.5 0 0" rpy="0.1 0 0"/><axis xyz="0 1 0"/>{limit}{mimic}</joint>
      <joint name="j2" type="revolute"><parent link="l2"/><child link="l3"/>
        <origin xyz="0.4 0 0.05"/><axis xyz="0 0 1"/>{limit}</joint>
      <joint name="t" type="fixed"><parent link="l3"/><child link="tip"/>
        <origin xyz="0.2 0 0"/></joint>
    </robot>"""


def test_a_mimic_joint_follows_its_master(tmp_path):
    (tmp_path / "mimic.urdf").write_text(
        _three_joints('<mimic joint="j1" multiplier="0.5" offset="0.1"/>')
    )
    (tmp_path / "plain.urdf").write_text(_three_joints(""))
    robot = cc.load_robot(tmp_path / "mimic.urdf")
    assert robot.dof == 2 and "m1.yaw" in robot.parameter_names
    q = cc.poses.uniform(robot, 30, seed=0)
    moved = np.column_stack([q[:, 0], 0.5 * q[:, 0] + 0.1, q[:, 1]])
    assert np.abs(oracle(tmp_path / "plain.urdf")(moved, "tip") - robot.fk(q)).max() < 1e-12
    changed = robot.with_deviations({"m1.x": 1e-3, "m1.yaw": 2e-3, "j1.offset": 1e-3})
    for name in ("out.urdf", "out.toml"):
        cc.save_robot(changed, tmp_path / name)
        assert np.abs(cc.load_robot(tmp_path / name).fk(q) - changed.fk(q)).max() < 1e-12
    marker = [[0.05, 0.02, 0.03]]
    true = changed.with_points(marker)
    meas = cc.simulate(true, cc.poses.uniform(robot, 60, seed=1), noise=2e-5, seed=2)
    cal = cc.identify(robot.with_points(marker), meas, "all")
    assert cal.success, cal.message
    q_new = cc.poses.uniform(robot, 200, seed=3)
    err = cal.robot.measured_points(q_new) - true.measured_points(q_new)
    assert np.sqrt(np.mean(np.sum(err**2, axis=-1))) < 2e-5 * np.sqrt(3)


TWO = """<robot name="two"{ns}>
  <link name="a"/><link name="b"/><link name="c"/><link name="tip"/>
  {before}
  <joint name="j1" type="revolute"><parent link="a"/><child link="b"/>
    <origin xyz="0 0 0.3"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j2" type="{kind}"><parent link="b"/><child link="c"/>
    {comment}<origin xyz="0.4
       0 0.1" rpy="0 0.2 0"/><axis xyz="{axis}"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <joint name="t" type="fixed"><parent link="c"/><child link="tip"/><origin xyz="0.2 0 0"/></joint>
</robot>"""


@pytest.mark.parametrize(
    "case",
    [
        {
            "before": '<transmission name="t2"><joint name="j2"><hardwareInterface>x'
            "</hardwareInterface></joint></transmission>"
        },
        {"comment": '<!-- was: <origin xyz="0 0 0"/> -->'},
        {"before": '<!-- <joint name="j2" type="fixed"><origin xyz="9 9 9"/></joint> -->'},
        {"ns": ' xmlns="http://www.ros.org"'},
        {"kind": "prismatic", "axis": "0 0.6 0.8"},
    ],
    ids=["transmission-first", "comment-in-joint", "commented-joint", "xmlns", "prismatic"],
)
def test_only_the_real_joints_origin_changes(tmp_path, case):
    fields = {"ns": "", "before": "", "comment": "", "kind": "revolute", "axis": "0 1 0"}
    fields.update(case)
    (tmp_path / "two.urdf").write_text(TWO.format(**fields))
    robot = cc.load_robot(tmp_path / "two.urdf")
    moved = robot.with_deviations({"j2.x": 2e-3, "j2.pitch": 3e-3, "j1.offset": 1e-3})
    cc.save_robot(moved, tmp_path / "out.urdf")
    q = cc.poses.uniform(robot, 20, seed=0)
    back = cc.load_robot(tmp_path / "out.urdf")
    assert np.abs(back.fk(q) - moved.fk(q)).max() < 1e-12
    if fields["kind"] == "prismatic":  # the joint slides along its axis, turned by its rpy
        shift = robot.position(np.array([0.0, 0.5])) - robot.position(np.array([0.0, 0.0]))
        c, s = np.cos(0.2), np.sin(0.2)
        axis = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]) @ [0.0, 0.6, 0.8]
        np.testing.assert_allclose(shift, 0.5 * axis, atol=1e-15)


def test_a_ur_urdf_with_a_calibrated_tool_says_the_file_cannot_hold_it(tmp_path):
    (tmp_path / "k.yaml").write_text(
        "kinematics:\n"
        + "".join(
            f"  {key}:\n" + "".join(f"    {f}: {v}\n" for f, v in zip(
                ("x", "y", "z", "roll", "pitch", "yaw"), values, strict=True))
            for key, values in zip(
                ("shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3"),
                [(0, 0, 0.16, 0, 0, 0), (0, 0, 0, 1.5708, 0, 0), (-0.42, 0, 0, 0, 0, 0),
                 (-0.39, 0, 0.13, 0, 0, 0), (0, -0.1, 0, 1.5708, 0, 0),
                 (0, 0.1, 0, 1.5708, 3.14159, 3.14159)],
                strict=True,
            )
        )
    )  # fmt: skip
    cc.save_robot(cc.load_robot(tmp_path / "k.yaml"), tmp_path / "ur.urdf")
    ur = cc.load_robot(tmp_path / "ur.urdf")
    with pytest.warns(cc.CalibrationWarning, match="loses up to 5.000 mm and 0.000°"):
        notes = cc.save_robot(ur.with_deviations({"tool_x": 5e-3}), tmp_path / "out.yaml")
    assert any("tool frame is not written" in n for n in notes)
    assert cc.save_robot(ur, tmp_path / "same.yaml") == []


def test_identify_records_the_chain_and_the_nominal_beside_the_output(tmp_path, monkeypatch):
    urdf = Path(__file__).parents[1] / "examples" / "kr16_2.urdf"
    (tmp_path / "robots").mkdir()
    (tmp_path / "robots" / "kr16.urdf").write_text(urdf.read_text())
    monkeypatch.chdir(tmp_path)
    robot = cc.load_robot("robots/kr16.urdf", tip_link="link6")
    meas = cc.simulate(
        robot.with_deviations({"joint2.x": 5e-4}), cc.poses.uniform(robot, 40, seed=1)
    )
    cc.write_csv("m.csv", meas, robot)
    argv = ["identify", "robots/kr16.urdf", "m.csv", "--tip-link", "link6", "-o", "out/cal.toml"]
    assert main(argv) == 0
    monkeypatch.chdir(tmp_path / "out")  # loaded from elsewhere, it still finds its nominal
    cal = cc.load_robot("cal.toml")
    assert cal.calibrated_chain == ("base_link", "link6")
    from casecal.model.catalog import nominal_of

    nominal = nominal_of(cal)
    assert nominal.urdf.tip_link == "link6"
    out = cc.compensate(cal, cc.poses.uniform(robot, 20, seed=2))
    assert out.ok.mean() > 0.7 and out.position_error[out.ok].max() < 1e-9
