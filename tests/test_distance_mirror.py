"""Distances cannot tell a robot from its mirror image (issue 19, case 11).

Distances between points do not change when the point cloud is reflected. A planar arm's
tool points lie nearly in a plane, so its mirror image is the same arm with the tilts out
of that plane flipped: both fit the distances, and a fit that lands on the wrong one, or on
the flat point between them, must not call itself a success.
"""

from __future__ import annotations

import dataclasses
import re

import numpy as np
import pytest

import casecal as cc
from casecal.identification.distances import (
    identify_distances,
    random_pairs,
    simulate_distances,
)

DEG = np.pi / 180
TILT = -0.07 * DEG  # the true α1 of the issue: −1.22 mrad


def aligned(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """RMS and largest distance (m) between point sets after the best rotation and
    translation (never a reflection): distances see no frame, but a mirror image is
    another shape."""
    a, b = a - a.mean(0), b - b.mean(0)
    U, _, Vt = np.linalg.svd(a.T @ b)
    R = U @ np.diag([1, 1, np.sign(np.linalg.det(U @ Vt))]) @ Vt
    e = np.linalg.norm(a @ R - b, axis=1)
    return float(np.sqrt(np.mean(e**2))), float(e.max())


def rr_case(nominal_tilt: float, noise: float):
    """The catalog's RR arm with a tool 0.1, 0.05, 0.2 m off the flange; the true arm
    deviates by 1 mm and 0.1° (seeded) and its α1 is −1.22 mrad."""
    rr = cc.load_robot("rr")
    tool = cc.Frame((0.1, 0.05, 0.2))
    nominal = dataclasses.replace(rr, tool=tool, auto_beta=False)
    nominal = nominal.with_parameters({"alpha1": nominal_tilt})
    rng = np.random.default_rng(0)
    dev = {
        n: rng.normal() * (0.1 * DEG if n.startswith(("theta", "alpha")) else 1e-3)
        for n in nominal.parameter_names
        if not n.startswith(("base", "tool", "beta"))
    }
    dev["alpha1"] = TILT - nominal_tilt
    true = nominal.with_deviations(dev)
    q = cc.poses.uniform(nominal, 60, seed=0)
    meas = simulate_distances(true, q, random_pairs(60, 300, seed=1), noise=noise, seed=3)
    return nominal, true, meas


def check_line(cal, name: str):
    return next(c for c in cal.audit.checks if c.name == name)


def test_rr_exact_distances_do_not_call_the_mirror_image_a_success():
    """A nominal drawn 0.1 mrad tilted: the fit lands on α1 = +1.22 mrad, the mirror of the
    true −1.22 mrad, and fits the distances exactly; main said success, 3.2 mm wrong."""
    nominal, true, meas = rr_case(nominal_tilt=0.1e-3, noise=0.0)
    cal = identify_distances(nominal, meas, "all")
    q_new = cc.poses.uniform(nominal, 300, seed=9)
    _, worst = aligned(cal.robot.position(q_new), true.position(q_new))
    assert abs(cal.robot.parameters["alpha1"] + TILT) < 1e-6  # the mirror: +1.22 mrad
    assert worst > 3e-3  # m: wrong by 3.2 mm at worst, 1.9 mm RMS
    assert not cal.success
    assert "the mirror image" in cal.message and "alpha1" in cal.message
    # the difference it states is the real error (the truth is the mirror here)
    stated = float(re.search(r"differ by up to ([\d.]+) mm", cal.message).group(1)) * 1e-3
    assert 0.8 * worst < stated < 1.25 * worst


def test_rr_noisy_distances_count_the_tilt_in_the_predicted_error():
    """A flat nominal and σ = 0.01 mm: the tilts are blind at the flat point (their effect
    on distances is second order, below the noise) and main held them there, called it a
    success and said nothing of the error: the shape 0.97 mm RMS wrong."""
    nominal, true, meas = rr_case(nominal_tilt=0.0, noise=1e-5)
    cal = identify_distances(nominal, meas, "all")
    q_new = cc.poses.uniform(nominal, 300, seed=9)
    rms, _ = aligned(cal.robot.position(q_new), true.position(q_new))
    assert rms > 0.8e-3
    assert not cal.success
    assert "alpha1" in cal.message
    prediction = check_line(cal, "prediction no worse than uncalibrated").text
    predicted = float(re.search(r"joint limits ([\d.e+-]+) mm", prediction).group(1)) * 1e-3
    assert predicted > 0.5 * rms  # the tilt the data cannot see is in the prediction


def planar_case(seed: int):
    """A random planar arm (2 to 4 revolute joints, all axes parallel, a tool anywhere
    within 0.2 m), deviations up to 2 mm and 0.5° on every DH parameter (none on the tilts
    in about a third of the cases: a truly flat arm), σ 0 or 0.01 mm, 60 poses, 300 pairs."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 5))
    joints = []
    for _ in range(n):
        half = rng.uniform(90, 170) * DEG
        joints.append(
            cc.Joint(
                "R",
                a=rng.uniform(0.1, 0.6),
                alpha=0.0,
                d=0.0 if rng.random() < 0.5 else rng.uniform(-0.3, 0.3),
                theta=float(rng.choice([0.0, np.pi / 2, -np.pi / 2])),
                limits=(-half, half),
            )
        )
    arm = cc.Robot(f"planar{n}", tuple(joints), convention="dh")
    tool = cc.Frame(tuple(rng.uniform(-0.2, 0.2, 3)))
    nominal = dataclasses.replace(arm, tool=tool, auto_beta=False)
    dev = {}
    for name in nominal.parameter_names:
        if name.startswith(("base_", "tool_")):
            continue
        is_length = name[0] in "ad" and not name.startswith("alpha")
        dev[name] = rng.uniform(-2e-3, 2e-3) if is_length else rng.uniform(-0.5, 0.5) * DEG
    if rng.random() < 0.3:
        dev = {k: (0.0 if k.startswith(("alpha", "beta")) else v) for k, v in dev.items()}
    true = nominal.with_deviations(dev)
    sigma = 0.01e-3 if rng.random() < 0.5 else 0.0
    q = cc.poses.uniform(nominal, 60, seed=seed + 1)
    meas = simulate_distances(true, q, random_pairs(60, 300, seed=seed), sigma, seed=seed + 2)
    return nominal, true, meas, sigma


def monte_carlo_shape_error(cal, q, draws: int = 30) -> float:
    """RMS shape error (m) of robots drawn from the fit's covariance, after the best rigid
    motion: what the covariance predicts, by sampling rather than linear algebra."""
    if not cal.estimated:
        return 0.0
    rng = np.random.default_rng(0)
    base = cal.robot.position(q)
    errors = []
    for x in rng.multivariate_normal(np.zeros(len(cal.estimated)), cal.covariance, draws):
        drawn = cal.robot.with_deviations(dict(zip(cal.estimated, x, strict=True)))
        errors.append(aligned(drawn.position(q), base)[0])
    return float(np.sqrt(np.mean(np.square(errors))))


def judge(seed: int) -> tuple[str, str]:
    nominal, true, meas, sigma = planar_case(seed)
    cal = identify_distances(nominal, meas, "all")
    q_new = cc.poses.uniform(nominal, 300, seed=seed + 3)
    rms, _ = aligned(cal.robot.position(q_new), true.position(q_new))
    if not cal.success:
        return "refused", cal.message
    limit = 1e-8 if sigma == 0 else 1.5 * monte_carlo_shape_error(cal, q_new)
    detail = f"seed {seed}: shape {rms * 1e3:.3g} mm off, limit {limit * 1e3:.3g} mm"
    return ("reached" if rms <= limit else "SILENT"), detail


# seeds main called a success with the shape 1.2 to 9 mm wrong (14, 19, 27: noisy and
# exact, two and three joints), and one a flat arm reaches (23)
@pytest.mark.parametrize("seed", [14, 19, 23, 27])
def test_random_planar_arms_reach_the_shape_or_say_so(seed):
    verdict, detail = judge(seed)
    assert verdict != "SILENT", detail
    if seed == 23:
        assert verdict == "reached", detail  # a flat arm, exact distances: no false alarm


@pytest.mark.slow
def test_random_planar_arms_reach_the_shape_or_say_so_many():
    """60 seeded planar cases; main: 9 silent (a success with the shape 0.44 to 10.8 mm
    wrong)."""
    verdicts = [judge(seed) for seed in range(60)]
    silent = [d for v, d in verdicts if v == "SILENT"]
    assert not silent, silent


def test_a_spatial_arm_has_no_mirror_image_to_fear():
    """KR 15/2 (its axes not parallel): the mirror image of its tool points is no robot of
    its model, the check passes and the fit is a success."""
    robot = cc.load_robot("kr15_2").with_parameters({"tool_x": 0.05, "tool_y": 0.03, "tool_z": 0.1})
    rng = np.random.default_rng(4)
    truth = {
        n: rng.normal() * (0.05 * DEG if n.startswith(("theta", "alpha", "beta")) else 0.5e-3)
        for n in robot.parameter_names
        if not n.startswith(("base_", "tool_"))
    }
    true = robot.with_deviations(truth)
    q = cc.poses.uniform(robot, 60, seed=0)
    meas = simulate_distances(true, q, random_pairs(60, 300, seed=1), noise=1e-5, seed=2)
    cal = identify_distances(robot, meas, "all")
    assert cal.success, cal.message
    line = check_line(cal, "no mirror image fits as well")
    assert line.passed and "no robot of this model near the estimate" in line.text
    q_new = cc.poses.uniform(robot, 300, seed=9)
    rms, _ = aligned(cal.robot.position(q_new), true.position(q_new))
    assert rms < 1.5 * monte_carlo_shape_error(cal, q_new)
