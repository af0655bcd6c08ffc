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
