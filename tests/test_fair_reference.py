"""The benchmarks' fair numpy reference (benchmarks/fair_reference.py) against casecal.

Two independent implementations: the reference's frame-vector Jacobian against casecal's
compiled `Robot.position_jacobian`, and its batched Gauss-Newton against `casecal.identify`
on noise-free data, estimating the parameters casecal estimated. Small (500 poses).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

import casecal as cc

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from fair_reference import (
    column_names,
    fair_gauss_newton,
    frame_position_jacobian,
)

DH = ["theta*", "a*", "d*", "alpha*"]


@pytest.fixture(scope="module")
def puma():
    robot = cc.load_robot("puma560")
    nominal = [
        np.array([getattr(j, f) for j in robot.joints]) for f in ("theta", "d", "a", "alpha")
    ]
    q = cc.poses.uniform(robot, 500, seed=0)
    return robot, nominal, q


def test_jacobian_matches_casecal(puma):
    robot, nominal, q = puma
    J_cc, names = robot.position_jacobian(q, ["theta*", "d*", "a*", "alpha*"])
    p, J = frame_position_jacobian(*nominal, q)
    assert p.shape == (3, len(q)) and J.shape == (24, 3, len(q))
    order = column_names(6)
    J = J.transpose(2, 1, 0)[:, :, [order.index(n) for n in names]]  # (N, 3, k) like casecal
    assert np.abs(J - J_cc).max() <= 1e-12 * np.abs(J_cc).max()
    assert np.abs(p.T - cc.simulate(robot, q).positions).max() <= 1e-12


def test_jacobian_of_selected_columns_and_off_nominal(puma):
    robot, nominal, q = puma
    rng = np.random.default_rng(3)
    off = [v + rng.normal(scale=1e-3, size=v.shape) for v in nominal]
    deviated = robot.with_deviations(
        {
            f"{f}{i + 1}": off[k][i] - nominal[k][i]
            for k, f in enumerate(("theta", "d", "a", "alpha"))
            for i in range(6)
        }
    )
    J_cc, names = deviated.position_jacobian(q, names := ["theta4", "alpha6", "a3", "d2"])
    order = column_names(6)
    p, J = frame_position_jacobian(*off, q, columns=[order.index(n) for n in names])
    assert J.shape == (4, 3, len(q))
    assert np.abs(J.transpose(2, 1, 0) - J_cc).max() <= 1e-12 * np.abs(J_cc).max()
    assert np.abs(p.T - cc.simulate(deviated, q).positions).max() <= 1e-12


@pytest.mark.parametrize("batch", [64, 100_000])
def test_gauss_newton_matches_identify(puma, batch):
    pytest.importorskip("threadpoolctl")
    from threadpoolctl import threadpool_limits

    robot, nominal, q = puma
    names = cc.identify(robot, cc.simulate(robot, q), DH, method="svd").estimated
    rng = np.random.default_rng(1)
    # 0.1 mm and 0.1 mrad: the wrist's angles become visible and casecal estimates them
    truth = dict(zip(names, rng.normal(scale=1e-4, size=len(names)), strict=True))
    meas = cc.simulate(robot.with_deviations(truth), q)
    cal = cc.identify(robot, meas, DH)
    assert cal.success
    with threadpool_limits(1):
        x, iterations = fair_gauss_newton(*nominal, q, meas.positions, cal.estimated, batch=batch)
    x_cc = np.array([cal.deviations[n] for n in cal.estimated])
    assert 1 < iterations < 10
    # the normal equations square the condition number (~1e4 here, from the barely visible
    # wrist angles): their rounding floor is ~2e-13 rad in those angles, 2e-9 relative to
    # the largest estimate; casecal (QR) returns them as exact zeros
    assert np.abs(x - x_cc).max() <= 1e-8 * np.abs(x_cc).max()
    assert len(cal.estimated) > len(names)  # the set grew where the fit ended: a real test
    # and the truth, to the same floor
    x_true = np.array([truth.get(n, 0.0) for n in cal.estimated])
    assert np.abs(x - x_true).max() <= 1e-8 * np.abs(x_true).max()
