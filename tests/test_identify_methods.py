"""Identification methods: agreement, noise statistics (Monte Carlo), options, result object."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import casecal as cc

DH = ["theta*", "d*", "a*", "alpha*"]


def puma_problem(n=60, seed=0, tool=None):
    """PUMA with random deviations on every DH parameter the poses can identify.

    Parameters in blind groups get none: a held parameter's true deviation would be
    absorbed by its group only to first order, and the rest would leak into the others.
    `tool`: a measured point on the tool (m), instead of the flange's centre.
    """
    robot = cc.load_robot("puma560")
    if tool is not None:
        robot = dataclasses.replace(robot, tool=cc.Frame(tool), auto_beta=False)
    rng = np.random.default_rng(seed)
    q = cc.poses.uniform(robot, n, seed=seed)
    visible = cc.observability(robot, q, DH).identifiable
    truth = {name: rng.normal(scale=2e-4 if name[0] in "ad" else 3e-4) for name in visible}
    return robot, truth, q, robot.with_deviations(truth)


def test_iterated_methods_agree_to_1e9_relative():
    robot, truth, q, true = puma_problem()
    meas = cc.simulate(true, q)
    results = {m: cc.identify(robot, meas, DH, m) for m in ("gauss-newton", "lm", "ipopt")}
    ref = results["gauss-newton"]
    scale = max(abs(v) for v in ref.deviations.values())
    for method, cal in results.items():
        assert cal.success, (method, cal.message)
        assert cal.estimated == ref.estimated
        diff = max(abs(cal.deviations[n] - ref.deviations[n]) for n in ref.estimated)
        assert diff <= 1e-9 * scale, (method, diff / scale)
    # and they found the truth: the identifiable parameters, and zero for the blind groups
    for name in ref.estimated:
        assert ref.deviations[name] == pytest.approx(truth.get(name, 0.0), rel=1e-7, abs=1e-13)


def test_standard_errors_match_monte_carlo_spread():
    """6-axis robot, uniform poses, sigma = 0.05 mm: reported standard errors vs the spread
    of 200 repetitions (the sample std of 200 draws is itself uncertain by about 5 %)."""
    sigma = 0.05e-3
    robot, _, q, true = puma_problem(n=40, seed=1)
    exact = cc.simulate(true, q)
    rng = np.random.default_rng(123)
    estimates, reported, sets = [], [], set()
    for _ in range(200):
        noisy = cc.Measurements(q, exact.positions + rng.normal(scale=sigma, size=(40, 3)), sigma)
        cal = cc.identify(robot, noisy, DH, "gauss-newton")  # the truth's set, α included
        assert cal.success, cal.message
        sets.add(cal.estimated)
        estimates.append([cal.deviations[n] for n in cal.estimated])
        reported.append([cal.standard_errors[n] for n in cal.estimated])
    assert len(sets) == 1  # the same parameters every time: the rank does not follow the noise
    spread = np.std(np.array(estimates), axis=0, ddof=1)
    predicted = np.mean(np.array(reported), axis=0)
    ratio = predicted / spread
    assert np.all(np.abs(ratio - 1) < 0.2), dict(zip(cal.estimated, ratio.round(3), strict=True))
    assert cal.sigma_known


def test_unknown_sigma_uses_residual_scale():
    sigma = 0.03e-3
    # a tool point well off the wrist: every wrist angle is seen, nothing is held
    robot, _, q, true = puma_problem(n=80, seed=2, tool=(0.05, 0.02, 0.1))
    noisy = cc.simulate(true, q, noise=sigma, seed=5)
    known = cc.identify(robot, noisy, DH, "gauss-newton")
    unknown = cc.identify(robot, noisy, DH, "gauss-newton", noise=0.0)
    assert known.sigma_known and not unknown.sigma_known
    ratio = [unknown.standard_errors[n] / known.standard_errors[n] for n in known.estimated]
    # residual scale estimates sigma from 240 - k degrees of freedom: within ~15 %
    assert np.allclose(ratio, ratio[0]) and 0.85 < ratio[0] < 1.15


def test_ipopt_bounds_and_prior():
    robot, truth, q, true = puma_problem()
    meas = cc.simulate(true, q)
    free = cc.identify(robot, meas, DH, "ipopt")
    name = "a2"
    lo = truth[name] + 1e-4  # exclude the truth: the estimate must sit on the bound
    bounded = cc.identify(robot, meas, DH, "ipopt", bounds={name: (lo, lo + 1e-3)})
    assert bounded.deviations[name] == pytest.approx(lo, abs=1e-9)
    assert free.deviations[name] == pytest.approx(truth[name], abs=1e-10)
    # a very tight prior pulls toward nominal; a loose one changes nothing
    sigma = 0.01e-3  # a prior weighs against the measurement sigma
    tight = cc.identify(robot, meas, DH, "ipopt", noise=sigma, prior={name: 1e-9})
    loose = cc.identify(robot, meas, DH, "ipopt", noise=sigma, prior={name: 1.0})
    assert abs(tight.deviations[name]) < 0.05 * abs(truth[name])
    assert loose.deviations[name] == pytest.approx(truth[name], abs=1e-9)
    with pytest.raises(cc.CalibrationError, match="ipopt"):
        cc.identify(robot, meas, method="lm", bounds={name: (0, 1)})
    with pytest.raises(cc.CalibrationError, match="sigma"):
        cc.identify(robot, meas, DH, "ipopt", prior={name: 1.0})


def test_result_object(tmp_path):
    robot, truth, q, true = puma_problem(n=30)
    meas = cc.simulate(true, q, noise=0.01e-3, seed=1)
    cal = cc.identify(robot, meas, DH, "lm", truth=truth)
    assert cal.residuals.shape == (30, 3) and cal.residuals_before.shape == (30, 3)
    assert cal.rms < cal.rms_before and cal.max_error < cal.max_error_before
    assert cal.history[-1] <= cal.history[0] and len(cal.history) == cal.iterations + 1
    assert cal.covariance.shape == (len(cal.estimated),) * 2
    table = cal.table
    assert list(table.parameter) == list(cal.parameters)
    assert {
        "unit",
        "nominal",
        "deviation",
        "std_error",
        "ci95_low",
        "ci95_high",
        "synthetic",
        "error_pct",
    } <= set(table.columns)
    row = table.set_index("parameter").loc["a2"]
    assert row.unit == "mm" and row.deviation == pytest.approx(cal.deviations["a2"] * 1e3)
    # sigma is known here: the 95 % interval is the normal one, ±1.96 standard errors
    assert cal.sigma_known
    assert row.ci95_high - row.ci95_low == pytest.approx(2 * 1.959964 * row.std_error, rel=1e-6)
    text = str(cal.summary())
    assert "RMS before" in text and "mm" in text and "Notes:" in text
    assert cal.summary().to_frame().shape[0] == len(cal.parameters)
    # the calibrated robot reproduces the fitted positions
    np.testing.assert_allclose(meas.positions - cal.robot.position(q), cal.residuals, atol=1e-15)


def test_user_errors():
    robot, _, q, true = puma_problem(n=3)
    meas = cc.simulate(true, q)
    with pytest.raises(cc.CalibrationError, match="unknown method"):
        cc.identify(robot, meas, method="magic")
    with pytest.raises(cc.CalibrationError, match="fewer than"):
        cc.identify(robot, meas, "all")
    with pytest.raises(cc.CalibrationError, match="joints"):
        cc.identify(cc.load_robot("scorbot"), meas)


def test_gauss_newton_follows_a_curved_valley_without_crawling():
    """4,000 noisy PUMA poses: the second round adds parameters the data barely see, whose
    full steps overshoot. Halving them took 15 iterations; the watchdog takes the
    overshoot once and the next step lands lower. Same minimum as Levenberg-Marquardt's."""
    robot = cc.load_robot("puma560")
    dh = ["theta*", "a*", "d*", "alpha*"]
    q = cc.poses.uniform(robot, 4000, seed=0)
    names = cc.identify(robot, cc.simulate(robot, q[:2000]), dh, method="svd").estimated
    rng = np.random.default_rng(1)
    scale = [np.deg2rad(0.01) if n.startswith(("th", "al")) else 1e-4 for n in names]
    truth = dict(zip(names, rng.normal(size=len(names)) * scale, strict=True))
    meas = cc.simulate(robot.with_deviations(truth), q, noise=0.02e-3, seed=2)
    cal = cc.identify(robot, meas, dh)
    lm = cc.identify(robot, meas, dh, method="lm")
    assert cal.success, cal.message
    assert len(cal.estimated) > len(names)  # the barely visible ones joined
    assert cal.iterations <= 8
    assert cal.history[-1] <= lm.history[-1] * (1 + 1e-9)
