"""Issue 19, case 8: without a stated σ, a rigid model that misses gravity compliance no
longer passes. Exact data of an arm that bends under gravity, poses far apart in joint
space (uniform, 90-150): on main every fit passed with 0.25-0.82 mm residuals and a
held-out error 3-4x its prediction."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import casecal as cc
from casecal.model.parameters import select
from casecal.report.studies_compliance import INERTIALS


def heavy():
    robot = cc.load_robot("kr15_2").with_points([[0.05, 0.02, 0.1]])
    return dataclasses.replace(robot, inertials=INERTIALS, auto_beta=False)


@pytest.mark.parametrize("seed", range(3))
def test_a_rigid_model_of_a_bending_arm_fails_without_sigma(seed):
    rng = np.random.default_rng(seed)
    c2, c3 = rng.uniform(0.1e-6, 0.4e-6, 2)  # rad/(N·m): 0.02-0.11° of bending
    true = heavy().with_compliance([2, 3])
    true = true.with_deviations({"c2": c2, "c3": c3, "a2": 3e-4, "base_x": 1.0})
    q = cc.poses.uniform(heavy(), int(rng.integers(90, 151)), seed=seed)
    cal = cc.identify(heavy(), cc.simulate(true, q), "all")
    assert 1e-4 < cal.rms < 1e-3  # m: small enough to pass for an instrument's noise
    assert not cal.success
    failed = {c.name: c.text for c in cal.audit.failures}
    assert "smooth functions of the joint values" in failed["residual consistent with the noise"]
    # with the term it lacks, the same data fit
    fine = cc.identify(heavy().with_compliance([2, 3]), cc.simulate(true, q), "all")
    assert fine.success, fine.message


@pytest.mark.parametrize("name", ["puma560", "ur5e", "scorbot", "scara"])
def test_noise_without_sigma_still_passes(name):
    """Gaussian noise, σ not stated: what the smooth joint errors explain is chance."""
    robot = cc.load_robot(name)
    rng = np.random.default_rng(7)
    names = select(robot.parameter_names, ["theta*", "a*", "d*"])
    true = robot.with_deviations({n: rng.normal() * 3e-4 for n in names})
    q = cc.poses.uniform(robot, 120, seed=8)
    noisy = cc.simulate(true, q, noise=0.02e-3, seed=9)
    cal = cc.identify(robot, cc.Measurements(noisy.q, noisy.positions, 0.0), "all")
    assert cal.success, cal.message
    assert any("smooth functions" in line for line in cal.audit.lines())


def test_a_robust_loss_does_not_hide_the_bending():
    """With --loss huber the check had been skipped: the bending arm passed again."""
    true = heavy().with_compliance([2, 3]).with_deviations({"c2": 3e-7, "c3": 2e-7})
    q = cc.poses.uniform(heavy(), 110, seed=4)
    cal = cc.identify(heavy(), cc.simulate(true, q), "all", loss="huber")
    assert not cal.success
    assert "smooth functions" in cal.message


@pytest.mark.parametrize("seed", range(4))
def test_measured_orientations_without_sigma_raise_no_false_alarm(seed):
    """Orientation rows carry an arbitrary weight without σ: pooled with the positions in
    the F test, 9 of 60 correct fits failed (0.05 mm, 0.01 mrad noise)."""
    robot = cc.load_robot("puma560")
    rng = np.random.default_rng(seed)
    names = select(robot.parameter_names, ["theta*", "a*", "d*"])
    true = robot.with_deviations({n: rng.normal() * 3e-4 for n in names})
    q = cc.poses.uniform(robot, 150, seed=seed)
    noisy = cc.simulate(true, q, noise=0.05e-3, seed=seed, orientation_noise=1e-5)
    meas = cc.Measurements(noisy.q, noisy.positions, 0.0, orientations=noisy.orientations)
    cal = cc.identify(robot, meas, "all")
    assert cal.success, cal.message
