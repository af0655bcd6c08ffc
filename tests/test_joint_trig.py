"""The joint angles' cos and sin, computed per block of poses outside the per-pose code
(`casecal.model._trig`): as accurate as the library, the same bits from every backend and
batch size, and exact Jacobians through the chain rule."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_urdf import _three_joints

import casecal as cc
from casecal.model import _trig, kinematics

SPECIAL = np.concatenate(
    [
        np.arange(-40, 41) * np.pi / 4,  # the reduction's boundaries
        np.nextafter(np.arange(-40, 41) * np.pi / 4, np.inf),
        [0.0, -0.0, 1e-300, -5e-324, 1e5, -123456.789, 1048575.9, 1048576.5, 3e7, -1e300],
    ]
)


def test_cos_sin_are_as_accurate_as_the_library():
    rng = np.random.default_rng(0)
    angles = np.concatenate([rng.uniform(-20, 20, 200_000), rng.uniform(-2e6, 2e6, 20_000)])
    angles = np.concatenate([angles, SPECIAL])
    c, s = _trig.cos_sin(angles)
    # libm is within an ulp of the truth: 2.5e-16 allows 2 ulp of a value near 1 besides
    assert np.abs(c - np.cos(angles)).max() <= 2.5e-16
    assert np.abs(s - np.sin(angles)).max() <= 2.5e-16
    small = np.abs(angles) < 1e-3  # relative accuracy (2 ulp) where sin is tiny
    assert np.all(np.abs(s[small] - np.sin(angles[small])) <= 4.5e-16 * np.abs(s[small]))
    c, s = _trig.cos_sin(np.array([np.inf, -np.inf, np.nan]))
    assert np.isnan(c).all() and np.isnan(s).all()


def _chain_and_poses(robot, n, seed=0):
    q = cc.poses.uniform(robot, n, seed=seed)
    rng = np.random.default_rng(seed)
    q[: len(SPECIAL) // 6 * 6] += rng.choice(SPECIAL, q[: len(SPECIAL) // 6 * 6].shape)
    q[7, 2] = np.nan
    return kinematics.chain(robot.structure), q


@pytest.mark.parametrize("backend", ["numpy", "casadi"])
def test_compiled_kernels_give_the_other_backends_bits(backend, monkeypatch):
    """The C kernels compute the joints' cos and sin themselves, in vector loops; numpy and
    CasADi get them from `cos_sin`: the same bits, also at angles the reduction leaves to
    the library, and nan where a joint value is nan."""
    robot = cc.load_robot("puma560").with_points([[0.02, 0.01, 0.08]])
    chain, q = _chain_and_poses(robot, 900)
    p, cols = robot.vector(), chain.columns(tuple(chain.names))
    monkeypatch.setenv("CASECAL_BACKEND", "c")
    compiled = [chain.evaluate(k, q, p, cols) for k in ("points", "points_and_jacobian")]
    monkeypatch.setenv("CASECAL_BACKEND", backend)
    other = [chain.evaluate(k, q, p, cols) for k in ("points", "points_and_jacobian")]
    assert np.isnan(compiled[0][7]).all() and np.isnan(other[0][7]).all()  # the nan pose
    for mine, theirs in zip(compiled, other, strict=True):
        if backend == "numpy":  # the same arithmetic in the same order
            assert np.array_equal(mine, theirs, equal_nan=True)
        else:  # CasADi's own evaluation of the rest of the graph rounds its own way
            np.testing.assert_allclose(mine, theirs, rtol=0, atol=1e-14)


def _joint_jacobian_by_differences(robot, q, step=1e-6):
    cols = []
    for i in range(q.shape[1]):
        plus, minus = q.copy(), q.copy()
        plus[:, i] += step
        minus[:, i] -= step
        Tp, Tm = robot.fk(plus), robot.fk(minus)
        dpos = (Tp[:, :3, 3] - Tm[:, :3, 3]) / (2 * step)
        W = (Tp[:, :3, :3] - Tm[:, :3, :3]) / (2 * step) @ np.swapaxes(robot.fk(q)[:, :3, :3], 1, 2)
        cols.append(np.concatenate([dpos, np.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], 1)], 1))
    return np.stack(cols, axis=2)


def _robots(tmp: Path):
    (tmp / "mimic.urdf").write_text(_three_joints('<mimic joint="j1" multiplier="0.5"/>'))
    examples = Path(__file__).parents[1] / "examples"
    return {
        "dh": cc.load_robot("puma560").with_deviations({"theta2": 0.1, "alpha3": 0.02}),
        "mdh": cc.load_robot("rx90b_mdh"),
        "prismatic": cc.load_robot("scara"),
        "urdf": cc.load_robot(examples / "kr16_2.urdf").with_deviations({"joint3.offset": 0.2}),
        "urdf-mimic": cc.load_robot(tmp / "mimic.urdf"),
    }


@pytest.mark.parametrize("name", ["dh", "mdh", "prismatic", "urdf", "urdf-mimic"])
@pytest.mark.parametrize("backend", ["c", "casadi"])
def test_joint_and_offset_jacobians_match_differences(name, backend, tmp_path, monkeypatch):
    """∂/∂q and ∂/∂theta (URDF: the joint offset) reach the per-pose cos and sin by the
    chain rule, in the compiled kernels and in CasADi's own evaluation, against central
    differences of the pose (position and rotation)."""
    from test_jacobian import finite_difference_jacobians

    robot = _robots(tmp_path)[name]
    chain = kinematics.chain(robot.structure)
    assert chain.joint_trig, "the structure should take its joint angles' cos and sin"
    monkeypatch.setenv("CASECAL_BACKEND", backend)
    q = cc.poses.uniform(robot, 300, seed=1)
    J = chain.evaluate("joint_jacobian", q, robot.vector())
    np.testing.assert_allclose(J, _joint_jacobian_by_differences(robot, q), rtol=0, atol=1e-7)
    offsets = [chain.names[k] for _, k in chain.joint_trig]
    Jx, names = robot.pose_jacobian(q, offsets)
    FDp, FDr = finite_difference_jacobians(robot, q, names)
    np.testing.assert_allclose(Jx[:, :3], FDp, rtol=0, atol=1e-7)
    np.testing.assert_allclose(Jx[:, 3:], FDr, rtol=0, atol=1e-7)
