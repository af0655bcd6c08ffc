"""Robot files: catalog and user files load; a malformed file names the file, the key, the fix."""

from __future__ import annotations

import math

import numpy as np
import pytest

import casecal as cc

GOOD = """\
name = "my_arm"
convention = "dh"
length_unit = "mm"
angle_unit = "deg"
[[joints]]
type = "R"
a = 0.0
alpha = -90.0
d = 349.0
theta = 0.0
limits = [-170.0, 170.0]
[[joints]]
type = "P"
a = 100.0
alpha = 0.0
d = 0.0
limits = [0.0, 200.0]
[base]
xyz = [0.0, 0.0, 10.0]
rpy = [0.0, 0.0, 90.0]
[tool]
xyz = [0.0, 0.0, 100.0]
"""

REQUIRED = ["r", "rr", "rrr", "scara", "scorbot", "puma560", "kr15_2", "rx90b", "ur5e", "irb120"]


def test_catalog_holds_required_robots_and_each_cites_a_source():
    names = cc.robots()
    assert set(REQUIRED) <= set(names)
    for name in names:
        robot = cc.load_robot(name)
        assert robot.source, f"{name} cites no source"
        assert robot.dof == len(robot.joint_types)


def test_catalog_numbers_as_the_issue_states():
    puma = cc.load_robot("puma560")
    assert puma.joints[0].d == pytest.approx(0.6718, abs=1e-4)
    assert cc.load_robot("scara").joint_types == "RRPR"
    assert cc.load_robot("scorbot").dof == 5


def test_user_file_in_mm_and_degrees_is_converted_to_si(write_toml):
    robot = cc.load_robot(write_toml(GOOD))
    assert robot.name == "my_arm" and robot.joint_types == "RP"
    assert robot.joints[0].d == pytest.approx(0.349)
    assert robot.joints[0].alpha == pytest.approx(-math.pi / 2)
    assert robot.joints[0].limits == pytest.approx((-170 * math.pi / 180, 170 * math.pi / 180))
    assert robot.joints[1].limits == pytest.approx((0.0, 0.2))  # prismatic: a length
    assert robot.base.xyz == pytest.approx((0, 0, 0.01))
    assert robot.base.rpy == pytest.approx((0, 0, math.pi / 2))
    assert robot.tool.xyz == pytest.approx((0, 0, 0.1))


def test_toml_writer_round_trips_exactly(write_toml):
    robot = cc.load_robot("scorbot").with_deviations(
        {"beta2": 1e-3, "tool_z": 0.05, "base_rz": 0.2}
    )
    again = cc.load_robot(write_toml(cc.robot_to_toml(robot)))
    assert again.parameters == robot.parameters
    q = cc.poses.uniform(robot, 5, seed=0)
    np.testing.assert_array_equal(again.fk(q), robot.fk(q))


@pytest.mark.parametrize(
    ("edit", "needles"),
    [
        (lambda s: s.replace('convention = "dh"\n', ""), ["convention", "dh"]),
        (lambda s: s.replace('convention = "dh"', 'convention = "xyz"'), ["convention", "mdh"]),
        (
            lambda s: s.replace('length_unit = "mm"', 'length_unit = "inch"'),
            ["length_unit", "inch"],
        ),
        (lambda s: s.replace("a = 100.0", 'a = "100"'), ["joints[2].a", "number"]),
        (lambda s: s.replace("d = 349.0", "d = nan"), ["joints[1].d", "finite"]),
        (lambda s: s.replace("a = 100.0\n", ""), ["joints[2]", "'a'"]),
        (lambda s: s.replace('type = "P"', 'type = "X"'), ["joints[2].type", "R"]),
        (lambda s: s.replace("alpha = -90.0", "alpah = -90.0"), ["alpah", "joints[1]"]),
        (lambda s: s.replace("[-170.0, 170.0]", "[170.0, -170.0]"), ["limits", "min"]),
        (lambda s: s.replace("[-170.0, 170.0]", "[1.0]"), ["limits", "[min, max]"]),
        (
            lambda s: s.replace("rpy = [0.0, 0.0, 90.0]", "rpy = [0.0, 90.0]"),
            ["[base].rpy", "three"],
        ),
        (lambda s: s.split("[[joints]]")[0], ["joints", "[[joints]]"]),
        (lambda s: s.replace("name = ", "name = = "), ["TOML"]),
    ],
)
def test_malformed_file_names_file_key_and_fix(write_toml, edit, needles):
    path = write_toml(edit(GOOD), name="broken_arm.toml")
    with pytest.raises(cc.CalibrationError) as info:
        cc.load_robot(path)
    message = str(info.value)
    assert "broken_arm.toml" in message
    for needle in needles:
        assert needle in message, message


def test_unknown_robot_and_missing_file():
    with pytest.raises(cc.CalibrationError, match=r"unknown robot 'nope'.*puma560"):
        cc.load_robot("nope")
    with pytest.raises(cc.CalibrationError, match="does not exist"):
        cc.load_robot("/no/such/arm.toml")


def test_robot_is_immutable_and_deviations_make_a_new_robot():
    robot = cc.load_robot("puma560")
    with pytest.raises(AttributeError):
        robot.name = "x"  # type: ignore[misc]
    true = robot.with_deviations({"theta1": 1.745e-4, "a2": -2e-4})
    assert robot.parameters["a2"] == pytest.approx(0.4318)
    assert true.parameters["a2"] == pytest.approx(0.4318 - 2e-4, abs=1e-15)
    assert true.parameters["theta1"] == pytest.approx(1.745e-4)
    assert true.structure == robot.structure
    with pytest.raises(cc.CalibrationError, match="no parameter 'a9'"):
        robot.with_deviations({"a9": 1.0})
    with pytest.raises(cc.CalibrationError, match="not finite"):
        robot.with_deviations({"a1": float("nan")})


def test_wrong_joint_values_are_refused():
    robot = cc.load_robot("scorbot")
    with pytest.raises(cc.CalibrationError, match="5 joints"):
        robot.fk(np.zeros(6))
    with pytest.raises(cc.CalibrationError, match="not finite"):
        robot.position(np.array([[0, 0, np.nan, 0, 0]]))


def test_hayati_beta_sits_where_consecutive_axes_are_parallel():
    # standard DH: link i carries beta_i when axes of joints i and i+1 are parallel
    assert [n for n in cc.load_robot("puma560").parameter_names if "beta" in n] == ["beta2"]
    assert [n for n in cc.load_robot("scorbot").parameter_names if "beta" in n] == [
        "beta2",
        "beta3",
    ]
    assert [n for n in cc.load_robot("scara").parameter_names if "beta" in n] == [
        "beta1",
        "beta2",
        "beta3",
    ]
    # modified DH: row i holds alpha_{i-1}, so the same PUMA axes 2 and 3 give beta3
    assert [n for n in cc.load_robot("puma560_craig").parameter_names if "beta" in n] == ["beta3"]
