"""Calibrate until good enough: the prediction is honest, and good poses need fewer."""

from __future__ import annotations

import numpy as np

import casecal as cc
from casecal.design.campaign import calibrate_until, pool_measure
from casecal.studies.engine import Grid, truth_for

SIGMA = 0.02e-3


def test_campaign_reaches_threshold_and_keeps_its_promise():
    robot = cc.load_robot("kr15_2")
    true = robot.with_deviations(truth_for(Grid(robots=("kr15_2",)), robot, 0))
    runs = {}
    for order in ("optimal", "uniform"):
        runs[order] = calibrate_until(
            robot,
            lambda q: cc.simulate(true, q, noise=SIGMA, seed=len(q)),
            threshold=0.05e-3,
            order=order,
            max_poses=120,
        )
        assert runs[order].reached, str(runs[order])
        # the promise: the actual 95 % error on new poses is under the threshold too
        q_new = cc.poses.uniform(robot, 300, seed=5)
        e = np.linalg.norm(
            runs[order].calibration.robot.position(q_new) - true.position(q_new), axis=1
        )
        assert np.quantile(e, 0.95) < 0.05e-3
    assert runs["optimal"].n_poses <= runs["uniform"].n_poses
    predictions = [p for _, p in runs["uniform"].history]
    assert predictions == sorted(predictions, reverse=True)  # more poses, smaller prediction


def test_campaign_from_a_pool_of_measured_poses():
    robot = cc.load_robot("puma560")
    true = robot.with_deviations({"a2": 2e-4, "theta3": 1e-4, "d4": -1e-4})
    pool = cc.simulate(true, cc.poses.uniform(robot, 300, seed=1), noise=SIGMA, seed=2)
    candidates, measure = pool_measure(pool)
    run = calibrate_until(robot, measure, threshold=0.08e-3, candidates=candidates)
    assert run.reached and run.n_poses < 100
    assert set(map(tuple, run.measurements.q)) <= set(map(tuple, pool.q))


def test_a_model_that_does_not_fit_cannot_claim_the_threshold():
    """A pool measured in a far instrument frame, fitted without frame parameters: the
    covariance alone would promise a small error; the residuals say otherwise."""
    robot = cc.load_robot("puma560")
    true = robot.with_deviations({"base_x": 2.0, "base_rz": 1.0, "a2": 2e-4})
    pool = cc.simulate(true, cc.poses.uniform(robot, 200, seed=1), noise=SIGMA, seed=2)
    candidates, measure = pool_measure(pool)
    run = calibrate_until(robot, measure, threshold=0.1e-3, candidates=candidates, max_poses=30)
    assert not run.reached


def test_no_pose_is_measured_twice():
    robot = cc.load_robot("puma560")
    true = robot.with_deviations({"a2": 2e-4})
    pool = cc.simulate(true, cc.poses.uniform(robot, 80, seed=1), noise=0.3e-3, seed=2)
    candidates, measure = pool_measure(pool)
    for order in ("optimal", "uniform"):
        run = calibrate_until(
            robot, measure, threshold=1e-6, order=order, candidates=candidates, max_poses=60
        )
        assert len({tuple(row) for row in run.measurements.q}) == run.n_poses
