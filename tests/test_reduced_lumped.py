"""Lumped gravity terms that do not over-fit (issue 22, item 5): the exact redundancy of the
lumped set removed, then the terms that predict chosen by cross-validation."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import casecal as cc
from casecal.identification.lumped_select import ReducedLumped, select_lumped
from casecal.model import kinematics
from casecal.model.lumped_basis import lumped_subset, reduced_lumped_terms

SIGMA = 0.03e-3
# two reflectors on the flange, as a tracker measures a medium arm
POINTS = [[0.05, 0.02, 0.1], [-0.04, 0.03, 0.08]]
# a Stäubli RX90-class arm (0.45 + 0.45 m links, about 70 kg moving, 6 kg on the flange):
# per body (mass kg, centre of mass in its frame m)
INERTIALS = (
    (25.0, (0.0, 0.0, 0.05)),
    (20.0, (-0.22, 0.0, 0.12)),
    (10.0, (0.0, -0.03, 0.02)),
    (8.0, (0.0, 0.0, -0.2)),
    (3.0, (0.0, 0.02, 0.0)),
    (6.0, (0.02, 0.0, 0.08)),
)
COMPLIANCE = {"c2": 2e-6, "c3": 3e-6, "c4": 5e-6, "c5": 1e-5}  # rad/(N·m)


def rigid():
    return cc.load_robot("rx90b").with_points(POINTS)


def true_robot(compliance=COMPLIANCE, seed=0):
    """The simulated arm: masses known to the simulation only, 0.2 mm / 0.01° deviations."""
    heavy = dataclasses.replace(rigid(), inertials=INERTIALS, auto_beta=False)
    robot = heavy.with_compliance(list(range(2, 6)))
    rng = np.random.default_rng(seed)
    deviations = {
        n: rng.normal() * 2e-4 for n in robot.parameter_names if n[0] in "tad" and "_" not in n
    }
    deviations.update(base_x=1.5, base_y=-0.8, base_rz=0.5, **compliance)
    return robot.with_deviations(deviations)


def points_jacobian(robot, q):
    chain = kinematics.chain(robot.structure)
    p = robot.vector()
    J = chain.evaluate("points_jacobian", q, p, chain.columns(robot.parameter_names), anchor=p)
    return J.reshape(-1, J.shape[-1])


def least_squares_residual(J, y) -> float:
    norms = np.linalg.norm(J, axis=0)
    J = J[:, norms > 1e-12 * norms.max()] / norms[norms > 1e-12 * norms.max()]
    beta = np.linalg.lstsq(J, y, rcond=None)[0]
    return float(np.linalg.norm(y - J @ beta))


def test_the_reduced_terms_span_what_the_full_set_spans():
    robot = rigid()
    full = robot.with_compliance()  # no masses: lumped terms, 56 on joints 2-5
    terms = reduced_lumped_terms(robot)
    reduced = robot.with_terms(*terms)
    full_names = {n for t in full.terms for n in t.parameters}
    kept = [n for t in terms for n in t.parameters]
    assert len(full_names) == 56 and len(kept) == 28 and set(kept) <= full_names
    # other poses than the ones the reduction sampled, and any data: the same best fit
    q = cc.poses.uniform(robot, 60, seed=7)
    y = np.random.default_rng(3).normal(size=60 * 6)
    r_full = least_squares_residual(points_jacobian(full, q), y)
    r_reduced = least_squares_residual(points_jacobian(reduced, q), y)
    assert abs(r_full - r_reduced) <= 1e-9 * r_full
    # and one term fewer is a different model: the comparison can tell
    fewer = robot.with_terms(*terms[1:], lumped_subset(2, 6, terms[0].parameters[1:]))
    r_fewer = least_squares_residual(points_jacobian(fewer, q), y)
    assert r_fewer - r_full > 1e-3 * r_full


def test_the_reduced_fit_equals_the_full_fit():
    true = true_robot()
    q = cc.poses.uniform(true, 60, seed=1)
    meas = cc.simulate(true, q, noise=SIGMA, seed=2)
    full = cc.identify(rigid().with_compliance(), meas, "all", method="gauss-newton")
    reduced = cc.identify(
        rigid().with_terms(*reduced_lumped_terms(rigid())), meas, "all", method="gauss-newton"
    )
    assert len(reduced.estimated) <= len(full.estimated)
    assert reduced.rms == pytest.approx(full.rms, rel=1e-9)


@pytest.fixture(scope="module")
def forty_poses():
    """The arm bending by 0.1 to 0.7 mm, measured at 40 poses; 150 others held out."""
    true = true_robot()
    q = cc.poses.uniform(true, 40, seed=1)
    meas = cc.simulate(true, q, noise=SIGMA, seed=2)
    q_new = cc.poses.uniform(true, 150, seed=9)
    held = cc.simulate(true, q_new, noise=SIGMA, seed=10)
    straight = true.with_parameters(dict.fromkeys(COMPLIANCE, 0.0))
    bend = np.linalg.norm(true.measured_points(q) - straight.measured_points(q), axis=-1)
    assert 0.1e-3 < np.median(bend) < 0.5e-3  # a medium arm's bending, not a heavy one's
    return true, meas, held


def held_out_rms(robot, meas, held) -> float:
    cal = cc.identify(robot, meas, "all")
    miss = cal.robot.measured_points(held.q) - held.positions
    return float(np.sqrt(np.mean(np.sum(miss**2, axis=-1))))


def noise_floor(true, meas) -> float:
    """The held-out RMS per point (m) that the noise alone leaves to a fit of the true
    model: σ√3 of the fresh measurements, and the spread of estimating the p parameters
    the poses determine from N poses of m points, σ√(p / (N m)) averaged over the workspace.
    p is the rank of the true robot's Jacobian at the poses (numpy, not the fit)."""
    J = points_jacobian(true, meas.q)
    s = np.linalg.svd(J / np.maximum(np.linalg.norm(J, axis=0), 1e-300), compute_uv=False)
    p = int(np.sum(s > 1e-8 * s[0]))
    n_poses, m = meas.positions.shape[:2]
    return SIGMA * np.sqrt(3 + p / (n_poses * m))


def test_the_chosen_terms_reach_the_noise_where_the_full_set_overfits(forty_poses):
    true, meas, held = forty_poses
    chosen = select_lumped(rigid(), meas)
    assert 1 <= len(chosen.names) <= 10, chosen.path
    floor = noise_floor(true, meas)
    assert SIGMA * np.sqrt(3) < floor < SIGMA * np.sqrt(3.5)  # about 34 parameters
    reduced = held_out_rms(chosen.robot, meas, held)
    full = held_out_rms(rigid().with_compliance(), meas, held)
    assert reduced <= 1.10 * floor, (reduced / floor, chosen.names)
    assert full > 1.05 * reduced, (full / floor, reduced / floor)


def test_compare_models_offers_the_reduced_set_and_chooses_it(forty_poses):
    _, meas, _ = forty_poses
    models = {
        "rigid": rigid(),
        "lumped, all": rigid().with_compliance(),
        "lumped, reduced": ReducedLumped(rigid()),
    }
    result = cc.compare_models(models, meas)
    table = result.table.set_index("model")
    # chosen again in each fold: the cross-validated error includes the choice
    assert table.cv_rms_mm["lumped, reduced"] < table.cv_rms_mm["lumped, all"]
    assert table.cv_rms_mm["lumped, reduced"] < table.cv_rms_mm["rigid"] / 3
    assert result.best == "lumped, reduced"


def test_a_robot_with_compliance_terms_is_refused():
    meas = cc.simulate(rigid(), cc.poses.uniform(rigid(), 10, seed=1), noise=SIGMA, seed=1)
    with pytest.raises(cc.CalibrationError, match="already has compliance terms"):
        select_lumped(rigid().with_compliance(), meas)
    with pytest.raises(cc.CalibrationError, match="not a lumped gravity term of joint 2"):
        lumped_subset(2, 6, ["g3_3m"])
    scara = cc.load_robot("scara")  # vertical axes: gravity loads none of them
    flat = cc.simulate(scara, cc.poses.uniform(scara, 10, seed=1), noise=SIGMA, seed=1)
    with pytest.raises(cc.CalibrationError, match="no joint carries gravity load"):
        select_lumped(scara, flat)


def test_a_chosen_set_survives_the_robot_file(tmp_path):
    terms = [lumped_subset(2, 6, ["g2_2m", "g2_3z"]), lumped_subset(3, 6, ["g3_3z"])]
    robot = rigid().with_terms(*terms)
    robot = robot.with_parameters({"g2_2m": 4e-4, "g2_3z": -1e-4, "g3_3z": 2e-4})
    cc.save_robot(robot, tmp_path / "r.toml")
    text = (tmp_path / "r.toml").read_text()
    assert 'lumped = ["g2_2m", "g2_3z", "g3_3z"]' in text
    back = cc.load_robot(tmp_path / "r.toml")
    assert back.parameter_names == robot.parameter_names
    q = cc.poses.uniform(robot, 10, seed=1)
    bend = np.abs(robot.measured_points(q) - rigid().measured_points(q)).max()
    assert bend > 1e-5  # the terms act, and act the same after the round trip
    assert np.abs(back.measured_points(q) - robot.measured_points(q)).max() == 0
    (tmp_path / "bad.toml").write_text(text.replace('"g3_3z"]', '"g4_3z"]'))
    with pytest.raises(cc.CalibrationError, match=r"not in compliance\.joints"):
        cc.load_robot(tmp_path / "bad.toml")


@pytest.mark.slow
def test_over_six_arms_the_chosen_terms_predict_better_than_all():
    """Six arms (deviations, poses and noise drawn anew): the choice never keeps more than
    ten terms, always predicts fresh poses better than the full set, and in the median
    is within 10 % of the noise floor of a fit of the true model."""
    ratios = []
    for seed in range(6):
        true = true_robot(seed=seed)
        meas = cc.simulate(true, cc.poses.uniform(true, 40, seed=1 + seed), SIGMA, seed=2 + seed)
        held = cc.simulate(true, cc.poses.uniform(true, 150, seed=9), SIGMA, seed=10)
        chosen = select_lumped(rigid(), meas)
        assert len(chosen.names) <= 10, (seed, chosen.names)
        reduced = held_out_rms(chosen.robot, meas, held)
        assert reduced < held_out_rms(rigid().with_compliance(), meas, held), seed
        ratios.append(reduced / noise_floor(true, meas))
    assert np.median(ratios) <= 1.10, ratios


def test_the_command_line_offers_the_terms_that_predict(forty_poses, tmp_path, capsys):
    from casecal.cli import main

    _, meas, _ = forty_poses
    cc.save_robot(rigid(), tmp_path / "rx90.toml")  # no masses: lumped terms
    cc.write_csv(tmp_path / "m.csv", meas, rigid())
    argv = ["compare", str(tmp_path / "rx90.toml"), str(tmp_path / "m.csv"), "--compliance"]
    assert main([*argv, "--folds", "3"]) == 0
    out = capsys.readouterr().out
    assert "chosen by cross-validation: + compliance, terms that predict" in out
