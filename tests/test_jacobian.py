"""Every Jacobian column against central differences of fk, on random robots (hypothesis)."""

from __future__ import annotations

import tomllib

import numpy as np
from conftest import random_robot_toml
from hypothesis import given, settings
from hypothesis import strategies as st

import casecal as cc
from casecal.model.catalog import robot_from_dict

REL_TOL = 1e-6
STEP = 1e-5  # m or rad: truncation ~STEP**2, rounding ~1e-16/STEP, both far below REL_TOL


def finite_difference_jacobians(robot: cc.Robot, q: np.ndarray, names: list[str]):
    """Central differences of fk: position (N, 3, k) and rotation vector (N, 3, k)."""
    p = robot.parameters
    R0 = robot.fk(q)[:, :3, :3]
    dpos, drot = [], []
    for name in names:
        plus = robot.with_parameters({name: p[name] + STEP}).fk(q)
        minus = robot.with_parameters({name: p[name] - STEP}).fk(q)
        dpos.append((plus[:, :3, 3] - minus[:, :3, 3]) / (2 * STEP))
        W = (plus[:, :3, :3] - minus[:, :3, :3]) / (2 * STEP) @ np.swapaxes(R0, 1, 2)
        W = 0.5 * (W - np.swapaxes(W, 1, 2))  # skew part: [omega]x
        drot.append(np.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], axis=1))
    return np.stack(dpos, axis=2), np.stack(drot, axis=2)


def assert_columns_close(J, FD, size):
    """Relative error per column; a column that vanishes is compared with the arm's size."""
    err = np.linalg.norm(J - FD, axis=1)  # (N, k)
    scale = np.maximum(np.linalg.norm(J, axis=1), 1e-3 * size)
    worst = float((err / scale).max())
    assert worst < REL_TOL, f"worst relative column error {worst:.2e}"


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1), convention=st.sampled_from(["dh", "mdh"]), n=st.integers(1, 6)
)
def test_jacobians_match_central_differences(seed, convention, n):
    rng = np.random.default_rng(seed)
    text, _ = random_robot_toml(rng, convention, n, length_unit="m", angle_unit="rad")
    robot = robot_from_dict(tomllib.loads(text))
    # random parameter values around the table, betas included (non-zero)
    robot = robot.with_deviations({k: rng.normal(scale=0.05) for k in robot.parameter_names})
    q = cc.poses.uniform(robot, 6, seed=seed)
    Jp, names = robot.position_jacobian(q)
    Jx, names_x = robot.pose_jacobian(q)
    assert names == names_x == list(robot.parameter_names)
    FDp, FDr = finite_difference_jacobians(robot, q, names)
    size = sum(abs(j.a) + abs(j.d) for j in robot.joints) + 1.0
    assert_columns_close(Jp, FDp, size)
    np.testing.assert_array_equal(Jx[:, :3], Jp)
    assert_columns_close(Jx[:, 3:], FDr, 1.0)


def test_subset_columns_equal_full_columns():
    robot = cc.load_robot("scorbot")
    q = cc.poses.uniform(robot, 5, seed=0)
    J_all, all_names = robot.position_jacobian(q, "all")
    J_sub, names = robot.position_jacobian(q, ["theta*", "a*", "d*"])
    assert names == [n for n in all_names if n[:-1] in ("theta", "a", "d")]
    idx = [all_names.index(n) for n in names]
    np.testing.assert_allclose(J_sub, J_all[:, :, idx], rtol=0, atol=1e-15)


def test_compiled_and_casadi_backends_agree(monkeypatch):
    robot = cc.load_robot("puma560")
    q = cc.poses.uniform(robot, 300, seed=4)  # above the compile threshold
    monkeypatch.setenv("CASECAL_BACKEND", "casadi")
    J_casadi, _ = robot.pose_jacobian(q)
    from casecal.model import _native

    # auto would answer by numpy until compiling pays (tests/test_deferred_compile.py)
    monkeypatch.setenv("CASECAL_BACKEND", "c" if _native.compiler() else "auto")
    J_auto, _ = robot.pose_jacobian(q)
    np.testing.assert_allclose(J_auto, J_casadi, rtol=0, atol=1e-14)


def test_known_geometry_of_a_planar_arm():
    """RR arm, unit links: closed-form columns a textbook gives, not read off our output."""
    robot = cc.load_robot("rr")
    q = np.array([0.3, -0.7])
    J, names = robot.position_jacobian(q, ["theta1", "theta2", "a1", "a2"])
    assert names == ["theta1", "a1", "theta2", "a2"]  # canonical order, whatever the request
    J = J[:, [0, 2, 1, 3]]
    s1, c1, s12, c12 = np.sin(0.3), np.cos(0.3), np.sin(-0.4), np.cos(-0.4)
    expected = np.array(
        [
            [-s1 - s12, -s12, c1, c12],
            [c1 + c12, c12, s1, s12],
            [0, 0, 0, 0],
        ]
    )
    np.testing.assert_allclose(J, expected, atol=1e-15)
