"""Random arms measured by distances alone: right or says so, on the one fitting path.

Each case: a random DH arm (`random_robots.random_arm`, 4–7 joints, R and P) deviating
from its table on every parameter (about 1 mm and 1 mrad), 60 random poses, 400 random
pairs, σ = 0.01 mm, everything asked for. Judged against the simulation's truth, which
the fit never sees: a success must predict the distances of 300 new pairs at the noise
floor (what distances can check: the arm's shape, not where it stands); a failure must
be said. A success that misses is silent: there must be none.

Measured on seeds 0–39 (2026-11-26): 35 at the floor (held-out 0.94–1.08 σ), 5 failed
naming a mirror image that fits the distances as well (distances cannot tell an arm from
its mirror image; the same 5 failed on the distance fit's earlier, parallel path, and its
estimates on the other seeds agree with the one path's to 1e-13 m or rad where both
estimate the same set), none silent.
"""

from __future__ import annotations

import numpy as np
import pytest
from random_robots import random_arm

import casecal as cc
from casecal.identification.distances import (
    identify_distances,
    random_pairs,
    simulate_distances,
)

SIGMA = 1e-5  # m


def judge(seed: int) -> tuple[str, str]:
    """("floor" | "failed" | "SILENT", detail)."""
    rng = np.random.default_rng(seed)
    arm = random_arm(rng, int(rng.integers(4, 8)), "dh")
    geometry = [n for n in arm.parameter_names if not n.startswith(("base_", "tool_"))]
    deviation = {n: rng.normal(0, 1e-3) for n in geometry}
    true = arm.with_deviations(deviation)
    q = cc.poses.uniform(arm, 60, seed=seed)
    meas = simulate_distances(true, q, random_pairs(60, 400, seed=seed), noise=SIGMA, seed=seed)
    try:
        cal = identify_distances(arm, meas, "all")
    except cc.CalibrationError as exc:
        return "failed", f"refused: {exc}"
    if not cal.success:
        return "failed", cal.message[:200]
    q_new = cc.poses.uniform(arm, 80, seed=seed + 1000)
    pairs = random_pairs(80, 300, seed=seed + 1)
    seen = simulate_distances(true, q_new, pairs, noise=SIGMA, seed=seed + 2).distances
    model = simulate_distances(cal.robot, q_new, pairs).distances
    rms = float(np.sqrt(np.mean((seen - model) ** 2)))
    detail = f"held-out {rms / SIGMA:.2f} σ ({arm.joint_types})"
    return ("floor" if rms <= 1.5 * SIGMA else "SILENT"), detail


def check(seeds, at_floor: float) -> None:
    """No silent case, and at least the share `at_floor` of them at the floor."""
    verdicts = {seed: judge(seed) for seed in seeds}
    silent = {s: d for s, (v, d) in verdicts.items() if v == "SILENT"}
    assert not silent, silent
    floor = sum(v == "floor" for v, _ in verdicts.values())
    assert floor >= at_floor * len(verdicts), verdicts


def test_random_arms_measured_by_distances():
    check(range(4), at_floor=0.5)  # seed 1's mirror image fails, and says so


@pytest.mark.slow
def test_more_random_arms_measured_by_distances():
    check(range(40), at_floor=0.85)


def test_identify_takes_distances_on_the_same_path():
    """`cc.identify` of distance measurements is `identify_distances`, and refuses the
    options distances do not take."""
    arm = cc.load_robot("kr15_2")
    q = cc.poses.uniform(arm, 30, seed=0)
    true = arm.with_deviations({"a2": 1e-3, "d4": -5e-4, "theta3": 2e-4})
    meas = simulate_distances(true, q, random_pairs(30, 200, seed=1), noise=SIGMA, seed=2)
    lines = []
    one, two = cc.identify(arm, meas, progress=lines.append), identify_distances(arm, meas)
    # the progress lines count the distances alone: the last RMS is about σ (0.01 mm)
    assert 0.008 < float(lines[-1].split("RMS ")[1].split(" mm")[0]) < 0.012, lines[-1]
    assert one.measured == "distances" and one.estimated == two.estimated
    assert one.deviations == two.deviations
    with pytest.raises(cc.CalibrationError, match="distance measurements do not take noise"):
        cc.identify(arm, meas, noise=1e-5)


def test_a_distance_fit_speaks_of_pairs():
    """The noise check's words about neighbouring residuals name pairs, not poses."""
    arm = cc.load_robot("kr15_2")
    q = cc.poses.uniform(arm, 30, seed=0)
    true = arm.with_deviations({"a2": 1e-3, "d4": -5e-4, "theta3": 2e-4})
    meas = simulate_distances(true, q, random_pairs(30, 200, seed=1), noise=SIGMA, seed=2)
    text = str(identify_distances(arm, meas).summary())
    assert "neighbouring pairs' residuals" in text and "neighbouring poses'" not in text
