"""Parameter selection, pose schedules and simulated measurements."""

from __future__ import annotations

import numpy as np
import pytest

import casecal as cc
from casecal.model.parameters import select, unit

NAMES = cc.load_robot("puma560").parameter_names


def test_family_glob_never_catches_alpha():
    assert select(NAMES, "a*") == [f"a{i}" for i in range(1, 7)]
    assert select(NAMES, "a") == select(NAMES, "a*")
    assert select(NAMES, "alpha*") == [f"alpha{i}" for i in range(1, 7)]
    assert select(NAMES, "base_*") == [
        "base_x",
        "base_y",
        "base_z",
        "base_rx",
        "base_ry",
        "base_rz",
    ]
    assert select(NAMES, "base_r*") == ["base_rx", "base_ry", "base_rz"]
    assert select(NAMES, "theta2, d3") == ["theta2", "d3"]
    assert select(NAMES, "all") == list(NAMES)
    assert select(NAMES, ["d*", "theta1"]) == ["theta1"] + [f"d{i}" for i in range(1, 7)]


def test_bad_selection_is_explained():
    with pytest.raises(cc.CalibrationError, match="'gamma1' matches no parameter"):
        select(NAMES, "gamma1")


def test_units():
    assert [unit(n) for n in ("theta1", "d1", "a2", "alpha3", "beta2", "base_x", "tool_rz")] == [
        "rad",
        "m",
        "m",
        "rad",
        "rad",
        "m",
        "rad",
    ]


def test_seed_schedule_follows_the_paper():
    scara = cc.load_robot("scara")
    q = cc.poses.seed_schedule(scara, 100)
    assert q.shape == (100, 4)
    np.testing.assert_allclose(q[:, 0], np.deg2rad(np.arange(100)))  # 0°, 1°, ... 99°
    np.testing.assert_allclose(q[:, 1], q[:, 0])
    np.testing.assert_allclose(q[:, 3], q[:, 0])
    assert q[0, 2] == 0.0 and q[-1, 2] == pytest.approx(0.21)  # quill: full extension at the end
    assert np.all(np.diff(q[:, 2]) > 0)


def test_uniform_poses_are_inside_limits_and_reproducible():
    robot = cc.load_robot("scorbot")
    q = cc.poses.uniform(robot, 2000, seed=5)
    lim = robot.limits
    assert np.all(q >= lim[:, 0]) and np.all(q <= lim[:, 1])
    np.testing.assert_array_equal(q, cc.poses.uniform(robot, 2000, seed=5))
    assert not np.array_equal(q, cc.poses.uniform(robot, 2000, seed=6))
    # spread over the whole range, not a corner of it
    assert np.all(q.min(axis=0) < lim[:, 0] + 0.05 * np.ptp(lim, axis=1))
    with pytest.raises(cc.CalibrationError, match="positive integer"):
        cc.poses.uniform(robot, 0)


def test_simulate_noise_free_and_noisy():
    nominal = cc.load_robot("puma560")
    true = nominal.with_deviations({"a2": 2e-4, "theta3": 1e-4})
    q = cc.poses.uniform(nominal, 4000, seed=1)
    exact = cc.simulate(true, q)
    np.testing.assert_array_equal(exact.positions, true.position(q))
    assert not np.allclose(exact.positions, nominal.position(q), atol=1e-5)
    sigma = 0.05e-3
    noisy = cc.simulate(true, q, noise=sigma, seed=3)
    err = noisy.positions - exact.positions
    # sample std of 12000 draws: within 3 % of sigma (its own std is ~0.65 %)
    assert np.std(err) == pytest.approx(sigma, rel=0.03)
    assert abs(np.mean(err)) < 5 * sigma / np.sqrt(err.size)
    np.testing.assert_array_equal(noisy.sigma, np.full((4000, 3), sigma))
    again = cc.simulate(true, q, noise=sigma, seed=3)
    np.testing.assert_array_equal(again.positions, noisy.positions)
    with pytest.raises(cc.CalibrationError, match="non-negative"):
        cc.simulate(true, q, noise=-1.0)
    with pytest.raises(ValueError):
        noisy.positions[0, 0] = 1.0  # read-only: a Measurements is a value
