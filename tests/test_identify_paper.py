"""The paper's claims (Simpson & Hayes): Table 1 on the Scorbot, planar arms, SCARA blind spots."""

from __future__ import annotations

import numpy as np
import pytest

import casecal as cc
from casecal.model.parameters import select

DEG = np.pi / 180
# Table 1 of the paper: the nine synthetic deviations (SI)
TABLE1 = {
    "theta1": 0.01 * DEG,
    "theta2": -0.005 * DEG,
    "theta3": 0.0075 * DEG,
    "theta4": -0.0085 * DEG,
    "a1": 0.15e-3,
    "a2": -0.2e-3,
    "a3": 0.125e-3,
    "d1": -0.175e-3,
    "d5": 0.25e-3,
}
ITERATED = ["gauss-newton", "lm", "ipopt"]
PAPER_SET = ["theta*", "a*", "d*"]


@pytest.fixture(scope="module")
def scorbot():
    return cc.load_robot("scorbot")


def table1_measurements(robot, n):
    return cc.simulate(robot.with_deviations(TABLE1), cc.poses.seed_schedule(robot, n))


def worst_error_pct(cal, names):
    errors = cal.errors()
    assert set(names) <= set(errors), f"not estimated: {set(names) - set(errors)}"
    return 100 * max(abs(errors[n]) for n in names)


@pytest.mark.parametrize("n_poses", [100, 25])
def test_table1_one_shot_svd_is_of_the_papers_order(scorbot, n_poses):
    cal = cc.identify(
        scorbot, table1_measurements(scorbot, n_poses), list(TABLE1), "svd", truth=TABLE1
    )
    worst = worst_error_pct(cal, TABLE1)
    # at least as good as the paper: worst 0.1813 % at 100 poses, "approximately 2 %" at 25;
    # and a single linearisation leaves second-order errors, so it is not exact either
    assert 1e-3 < worst < (0.1813 if n_poses == 100 else 2.0)
    assert cal.iterations == 1 and cal.success
    assert not cal.unidentifiable


@pytest.mark.parametrize("n_poses", [100, 25])
@pytest.mark.parametrize("method", ITERATED)
def test_table1_iterated_methods_are_exact(scorbot, method, n_poses):
    cal = cc.identify(
        scorbot, table1_measurements(scorbot, n_poses), list(TABLE1), method, truth=TABLE1
    )
    assert cal.success, cal.message
    assert worst_error_pct(cal, TABLE1) < 1e-6
    assert cal.rms < 1e-12  # m


@pytest.mark.parametrize("n_poses", [100, 25])
@pytest.mark.parametrize("method", ["svd", *ITERATED])
def test_table1_with_all_theta_a_d_reports_what_is_blind(scorbot, method, n_poses):
    cal = cc.identify(
        scorbot, table1_measurements(scorbot, n_poses), PAPER_SET, method, truth=TABLE1
    )
    # theta5: zero column; d2, d3, d4: parallel axes; theta4 with a4: tool point on the roll axis
    assert set(cal.unidentifiable) == {"theta5", "d2", "d3", "d4", "theta4", "a4"}
    texts = " | ".join(cal.observability.combinations)
    assert "d2 + d3 + d4" in texts
    assert any(set(s.members) == {"theta4", "a4"} for s in cal.observability.blind_spots)
    assert any(s.members == ("theta5",) for s in cal.observability.blind_spots)
    # held parameters stay at nominal, with no standard error
    for name in cal.held:
        assert cal.deviations[name] == 0.0 and np.isnan(cal.standard_errors[name])
    if method != "svd":
        # theta4 is estimated for its group (the first member) and truly carries the
        # group's deviation here (Δa4 = 0), so all nine come out exact
        assert worst_error_pct(cal, TABLE1) < 1e-6


def test_paper_claim_planar_arms_ten_poses():
    """R and RR: every theta and a within 0.01 % by one SVD, 1e-6 % iterated, from 10 poses,
    with deviations about four orders of magnitude below the (unit) link lengths."""
    for name in ("r", "rr"):
        robot = cc.load_robot(name)
        truth = {}
        for i in range(1, robot.dof + 1):
            truth[f"theta{i}"] = 0.5e-4 * (-1) ** i
            truth[f"a{i}"] = 0.6e-4 * (-1) ** (i + 1)
        meas = cc.simulate(robot.with_deviations(truth), cc.poses.seed_schedule(robot, 10))
        one_shot = cc.identify(robot, meas, ["theta*", "a*"], "svd", truth=truth)
        assert worst_error_pct(one_shot, truth) < 0.01, name
        for method in ITERATED:
            cal = cc.identify(robot, meas, ["theta*", "a*"], method, truth=truth)
            assert worst_error_pct(cal, truth) < 1e-6, (name, method)


def test_one_shot_error_is_second_order_as_the_paper_requires():
    """Why the paper needs small deviations: on the R arm, p = (a + Δa)(cos, sin)(q + Δθ), and
    one linearisation at nominal reads Δθ through the nominal lever a, so it returns
    Δθ (1 + Δa/a): the relative error of θ is Δa/a, second order in the deviations."""
    robot = cc.load_robot("r")
    for da in (1e-4, 1e-3):
        truth = {"theta1": 2e-4, "a1": da}
        meas = cc.simulate(robot.with_deviations(truth), cc.poses.seed_schedule(robot, 10))
        cal = cc.identify(robot, meas, ["theta*", "a*"], "svd", truth=truth)
        assert cal.errors()["theta1"] == pytest.approx(da / robot.joints[0].a, rel=0.02)


def test_scara_observability_names_theta4_and_vertical_offsets():
    robot = cc.load_robot("scara")
    obs = cc.observability(robot, cc.poses.seed_schedule(robot, 100))
    assert obs.parameters == tuple(select(robot.parameter_names, PAPER_SET))
    # the paper: theta4 does not move the tool point, and no vertical offset d is observable
    assert {"theta4", "d1", "d2", "d3", "d4"} <= set(obs.unidentifiable)
    vertical = [s for s in obs.blind_spots if set(s.members) == {"d1", "d2", "d3", "d4"}]
    assert len(vertical) == 1
    # z1 points up, z2 and z3 down (alpha2 = 180 deg): the height sees d1 + d2 - d3 - d4
    assert vertical[0].visible == "d1 + d2 - d3 - d4"
    assert {"theta1", "theta2"} <= set(obs.identifiable)


def test_scorbot_theta4_a4_coefficient_is_the_tool_distance():
    """theta4 rotates the tool point about an axis d5 away, exactly as a4 translates it."""
    robot = cc.load_robot("scorbot")
    obs = cc.observability(robot, cc.poses.uniform(robot, 50, seed=0))
    spot = next(s for s in obs.blind_spots if set(s.members) == {"theta4", "a4"})
    coefficient = float(spot.visible.split("+")[1].split("rad/m")[0])
    assert coefficient == pytest.approx(1 / robot.joints[4].d, rel=1e-3)  # 1/d5 = 6.891 rad/m
