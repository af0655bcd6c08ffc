"""How many parameters a 6-axis arm with base and tool can give up: the textbook counts.

For a serial arm with R revolute and P prismatic joints, base and tool frames, full pose
measurements identify 4R + 2P + 6 parameters; position alone 3 fewer (the tool's
orientation cannot be seen): 30 and 27 for an all-revolute 6-axis arm (Everett, Driels &
Mooring; Hollerbach & Wampler).
"""

from __future__ import annotations

import pytest

import casecal as cc


@pytest.mark.parametrize("name", ["puma560", "rx90b", "kr15_2", "ur5e"])
def test_identifiable_counts_of_six_axis_arms(name):
    # a tool point off the wrist axes, as any real tool has (at the wrist centre the
    # wrist's own parameters would not move the measured point at all)
    robot = cc.load_robot(name).with_parameters({"tool_x": 0.05, "tool_y": 0.03, "tool_z": 0.1})
    q = cc.poses.uniform(robot, 80, seed=0)
    position = cc.identify(robot, cc.simulate(robot, q), "all", "gauss-newton")
    pose = cc.identify(robot, cc.simulate(robot, q, orientation_noise=0.0), "all", "gauss-newton")
    assert position.observability.rank == 27
    assert pose.observability.rank == 30
    assert len(pose.estimated) == 30 and len(position.estimated) == 27


@pytest.mark.parametrize("name", ["puma560", "rx90b", "kr15_2", "ur5e"])
def test_observability_counts_for_position_and_pose(name):
    robot = cc.load_robot(name).with_parameters({"tool_x": 0.05, "tool_y": 0.03, "tool_z": 0.1})
    q = cc.poses.uniform(robot, 80, seed=0)
    assert cc.observability(robot, q, "all").rank == 27
    assert cc.observability(robot, q, "all", measurement="pose").rank == 30


def test_a_tilted_dependency_names_only_its_own_parameters():
    """Where an exact dependency is tilted a little (PUMA's d2, d3 along z1, z2 once
    alpha2 is off), the blind direction is d2 - d3 with a share of theta2, theta3; the
    other parameters' 1e-8 shares of it are rounding, not blindness: before, the text named
    every parameter blind and none identifiable."""
    tool = {"tool_x": 0.02, "tool_y": 0.01, "tool_z": 0.08}  # off the flange: wrist seen
    tilt = {"alpha2": 1e-5, "a3": 1e-4, "theta3": 1e-3, "alpha4": 1e-3}
    robot = cc.load_robot("puma560").with_deviations({**tool, **tilt})
    q = cc.poses.uniform(robot, 3000, seed=0)
    obs = cc.observability(robot, q, ["theta*", "a*", "d*", "alpha*"])
    assert obs.rank == 22
    wrist = {"theta6", "d6", "a6", "alpha6"}  # the tool frame's own blind combination
    assert set(obs.unidentifiable) == {"theta2", "d2", "theta3", "d3", *wrist}
    assert {"theta1", "a2", "a4", "alpha5"} <= set(obs.identifiable)
    groups = {frozenset(spot.members) for spot in obs.blind_spots}
    assert groups == {frozenset({"theta2", "d2", "theta3", "d3"}), frozenset(wrist)}
    tilted = next(spot for spot in obs.blind_spots if "d2" in spot.members)
    assert tilted.text.startswith("theta2, d2, theta3, d3: 1 combination is blind")
