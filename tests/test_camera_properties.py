"""Random arms seen by a camera: the fit is right or says it is not (issue 21).

Each case: a random DH arm (`random_robots.random_arm`) that deviates from its table on
every parameter (about 0.5 mm and 0.5 mrad), a camera fixed or on the flange at a random
distance and angle, a random lens a few pixels off its nominal, 50 random views that see
the whole 7 × 9 board, σ = 0.3 px. The fit asks for everything. Judged against the
simulation's truth, which the fit never sees: a success must predict 20 new views at the
noise floor and hold every estimate (or the combination it stands for) within its
standard errors; a failure must be said, naming what the views cannot determine. A success
outside either is silent: there must be none. Measured on seeds 0–39 (2026-11-26): 33
cases, 26 at the floor (held-out 0.97–1.04 σ, worst estimate 3.5 SE), 7 failed naming one
or two parameters the views leave wide (their calibrated arms were still better than the
nominal across the workspace: the audit is cautious there), none silent.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from random_robots import random_arm

import casecal as cc
from casecal.errors import CalibrationError
from casecal.observations.camera import Intrinsics
from casecal.observations.residuals import moved_setup
from casecal.observations.rig import rig_robot
from casecal.observations.simulate import CameraSetup, look_at, select_views, simulate_pixels
from casecal.observations.target import Checkerboard

SIGMA = 0.3  # px
FLOOR = 1.15  # held-out RMS per coordinate, in σ: the noise plus the estimates' own spread
Z_SILENT = 6.0  # an estimate this many standard errors off its truth is wrong


def _rotation_z(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def random_setup(rng, robot, q0, mode: str) -> CameraSetup:
    """A nominal camera and board that see each other at `q0`."""
    board = Checkerboard()
    lens = Intrinsics(
        rng.uniform(900, 1600), rng.uniform(900, 1600), rng.uniform(600, 680),
        rng.uniform(480, 540), k1=rng.uniform(-0.3, 0.1), k2=rng.uniform(-0.05, 0.15),
    )  # fmt: skip
    flange = robot.fk(q0)
    mount = np.eye(4)
    mount[:3, :3] = _rotation_z(rng.uniform(-np.pi, np.pi))
    mount[:3, 3] = [rng.uniform(-0.03, 0.03), rng.uniform(-0.03, 0.03), rng.uniform(0.03, 0.12)]
    distance = rng.uniform(0.4, 1.2)
    if mode == "eye_to_hand":  # board on the flange, camera in front of its face
        at = flange @ mount
        centre = at[:3, :3] @ board.centre + at[:3, 3]
        side = rng.normal(0, 0.15, 3)
        camera = look_at(centre - distance * (at[:3, 2] + side), centre)
        return CameraSetup(mode, camera, mount, lens, board)
    cam = flange @ mount  # camera on the flange, board in front of it
    target = np.eye(4)
    target[:3, :3] = cam[:3, :3] @ _rotation_z(rng.uniform(-0.3, 0.3))
    target[:3, 3] = cam[:3, 3] + distance * cam[:3, 2] - target[:3, :3] @ board.centre
    return CameraSetup(mode, mount, target, lens, board)


def case(seed: int):
    """(nominal arm, true arm, nominal setup, true setup, views, new views) or None when
    the random geometry has no views that see the board."""
    rng = np.random.default_rng(seed)
    arm = random_arm(rng, 6, "dh")
    if "R" not in arm.joint_types:
        return None
    lo, hi = np.array([j.limits for j in arm.joints]).T
    q0 = lo + (hi - lo) * rng.uniform(0.3, 0.7, arm.dof)
    mode = ("eye_to_hand", "eye_in_hand")[seed % 2]
    nominal = random_setup(rng, arm, q0, mode)
    geometry = [n for n in arm.parameter_names if not n.startswith(("base_", "tool_"))]
    true_arm = arm.with_deviations({n: rng.normal(0, 5e-4) for n in geometry})
    offsets = {n: rng.normal(0, 3e-3) for n in ("camera_x", "camera_y", "target_z")}
    offsets |= {n: rng.normal(0, 3e-3) for n in ("camera_wx", "target_wy", "target_wz")}
    offsets |= {"fx": rng.normal(0, 8), "fy": rng.normal(0, 8), "cx": rng.normal(0, 4)}
    offsets |= {"cy": rng.normal(0, 4), "k1": rng.normal(0, 0.01)}
    true_setup = moved_setup(nominal, offsets)
    try:
        q = select_views(arm, 70, nominal, seed=seed, q_centre=q0, spread=0.5, max_tilt=1.0)
        q = q[select_views_ok(true_arm, q, true_setup)][:70]
    except CalibrationError:
        return None
    if len(q) < 70:
        return None
    return arm, true_arm, nominal, true_setup, q[:50], q[50:]


def select_views_ok(robot, q, setup) -> np.ndarray:
    from casecal.observations.simulate import visible

    return visible(robot, q, setup, margin_px=2.0)


def judge(seed: int) -> tuple[str, str]:
    """("floor" | "failed" | "no case" | "SILENT", detail)."""
    made = case(seed)
    if made is None:
        return "no case", ""
    arm, true_arm, nominal, true_setup, q, q_new = made
    seen = cc.simulate_camera(true_arm, q, true_setup, SIGMA, seed=seed + 100)
    try:
        cal = cc.identify(arm, dataclasses.replace(seen, setup=nominal), "all")
    except CalibrationError as exc:
        return "failed", f"refused: {exc}"
    if not cal.success:
        return "failed", cal.message
    truth = rig_robot(true_arm, true_setup).deviations_from(rig_robot(arm, nominal), cal.parameters)
    cal = cal.compare_to(truth)
    z = {n: (cal.deviations[n] - cal.true_value(n)) / cal.standard_errors[n] for n in cal.estimated}
    worst = max(z, key=lambda n: abs(z[n]))
    exact = simulate_pixels(true_arm, q_new, true_setup)
    noisy = exact + np.random.default_rng(seed + 200).normal(0, SIGMA, exact.shape)
    held_out = np.sqrt(np.mean((noisy - simulate_pixels(cal.robot, q_new, cal.camera.setup)) ** 2))
    detail = f"held-out {held_out / SIGMA:.2f} σ, worst {worst} at {z[worst]:.1f} SE"
    if abs(z[worst]) > Z_SILENT or held_out > FLOOR * SIGMA:
        return "SILENT", detail  # a success off its truth, or not at the floor
    return "floor", detail


def check(seeds) -> None:
    """No silent case; every success at the floor; every failure names what the views
    cannot determine (a camera sees the board from a small region of the joint space, and
    a parameter that region leaves wide fails the audit rather than being guessed)."""
    verdicts = {seed: judge(seed) for seed in seeds}
    silent = {s: d for s, (v, d) in verdicts.items() if v == "SILENT"}
    assert not silent, silent
    cases = {s: vd for s, vd in verdicts.items() if vd[0] != "no case"}
    assert len(cases) >= 0.6 * len(verdicts), verdicts  # the generator makes real cases
    unexplained = {
        s: d
        for s, (v, d) in cases.items()
        if v == "failed" and not ("cannot determine" in d or "cannot tell" in d)
    }
    assert not unexplained, unexplained
    assert sum(v == "floor" for v, _ in cases.values()) >= 0.5 * len(cases), verdicts


def test_random_arms_seen_by_a_camera():
    check(range(6))


@pytest.mark.slow
def test_more_random_arms_seen_by_a_camera():
    check(range(6, 40))
