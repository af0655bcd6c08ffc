"""Measurements of several sessions (the instrument re-mounted between them), fitted together.

The references are independent of the session machinery: measurements are simulated
through one plain robot per session (`simulate` with `frames=`), rotations are compared
with scipy's Euler angles, the Jacobian with central differences of plain robots, and
the standard errors with the spread of Monte Carlo estimates.
"""

from __future__ import annotations

import dataclasses
import itertools
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import casecal as cc
from casecal.model.robot import Frame

ROOT = Path(__file__).resolve().parents[1]

PARAMETERS = "theta*,a*,d*,base"
ERRORS = ("theta2", "theta3", "theta4", "theta5", "a1", "a2", "a3", "d2", "d4", "d6", "a6")
"""Parameters given mm-level errors: not theta1 and d1, which only the base frames see."""


def nominal() -> cc.Robot:
    # a tool off the flange, so that the wrist's parameters move the measured point
    return cc.load_robot("puma560").with_parameters({"tool_x": 0.05, "tool_z": 0.12})


def truth_deviations(rng) -> dict:
    """About a millimetre (or a milliradian) on each of `ERRORS`."""
    return {n: float(rng.normal(0.0, 1e-3)) for n in ERRORS}


def frames_for(labels, rng) -> dict:
    """A random instrument placement per session: metres apart, turned tens of degrees."""
    return {
        label: Frame(tuple(rng.uniform(-2.5, 2.5, 3)), tuple(rng.uniform(-0.6, 0.6, 3)))
        for label in labels
    }


def campaign(n_sessions: int, seed: int, per_session: int = 50, noise: float = 5e-5):
    """(nominal, true deviations, frames by label, measurements) of one simulated campaign."""
    rng = np.random.default_rng(seed)
    nom = nominal()
    deviations = truth_deviations(rng)
    labels = [f"S{k + 1}" for k in range(n_sessions)]
    frames = frames_for(labels, rng)
    q = cc.poses.uniform(nom, per_session * n_sessions, seed=int(rng.integers(1 << 30)))
    session = np.repeat(labels, per_session)
    meas = cc.simulate(
        nom.with_deviations(deviations),
        q,
        noise,
        seed=int(rng.integers(1 << 30)),
        session=session,
        frames=frames,
    )
    return nom, deviations, frames, meas


def chart_errors(fitted: Frame, true: Frame) -> np.ndarray:
    """(x, y, z, δroll, δpitch, δyaw) taking `fitted` to `true`: the rotation's turn in
    the chart the standard errors are of (Rz(y0) Ry(p0) · Rz(δy) Ry(δp) · Rx(r0 + δr)),
    by scipy's Euler angles."""
    r0, p0, y0 = fitted.rpy
    turn = Rotation.from_euler("ZY", [y0, p0])
    M = turn.inv() * Rotation.from_euler("ZYX", true.rpy[::-1])
    dy, dp, roll = M.as_euler("ZYX")
    droll = (roll - r0 + np.pi) % (2 * np.pi) - np.pi
    return np.array([*np.subtract(true.xyz, fitted.xyz), droll, dp, dy])


# --- the fit ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def five():
    """Five sessions of 50 poses, fitted: (nominal, deviations, frames, meas, cal)."""
    nom, deviations, frames, meas = campaign(5, seed=11)
    cal = cc.identify(nom, meas, PARAMETERS, truth=deviations)
    return SimpleNamespace(nom=nom, deviations=deviations, frames=frames, meas=meas, cal=cal)


def test_five_sessions_recover_every_frame_and_the_robot(five):
    frames, cal = five.frames, five.cal
    assert cal.success, cal.message
    assert list(cal.sessions) == ["S1", "S2", "S3", "S4", "S5"]
    z = []
    for label, fit in cal.sessions.items():
        assert fit.n_poses == 50
        err = chart_errors(fit.base, frames[label])
        se = np.array(fit.base_standard_errors)
        assert np.all(np.isfinite(se)) and np.all(se > 0)
        z.append(err / se)
        # and in absolute terms: tens of micrometres, a few millidegrees
        assert np.all(np.abs(err[:3]) < 1e-4) and np.all(np.abs(err[3:]) < 1e-4)
    z = np.array(z)
    assert np.max(np.abs(z)) < 3.5, z
    assert 0.5 < np.sqrt(np.mean(z**2)) < 1.5, z
    # the calibrated robot's base is the first session's frame
    assert cal.robot.base == cal.sessions["S1"].base
    assert cal.robot.sessions == ()
    # the shared parameters: what each estimate stands for, within its standard error
    shared = [n for n in cal.estimated if not n.startswith("base_")]
    assert {"theta2", "a2", "d4", "theta5"} <= set(shared)
    zs = [(cal.deviations[n] - cal.true_value(n)) / cal.standard_errors[n] for n in shared]
    assert np.max(np.abs(zs)) < 4, dict(zip(shared, zs, strict=True))
    # the RMS error of every session is the noise's (√3 σ = 0.087 mm)
    for fit in cal.sessions.values():
        assert 0.06e-3 < fit.rms < 0.11e-3


def test_a_calibration_refits_from_its_own_names(five):
    """What `hold_poorly_determined` does: identify again from the result's nominal robot
    (a frame per session) and its parameter names (base_x@S2 …)."""
    cal = five.cal
    again = cc.identify(cal.nominal, five.meas, list(cal.parameters))
    assert again.parameters == cal.parameters and again.estimated == cal.estimated
    for n in cal.estimated:
        assert again.deviations[n] == pytest.approx(cal.deviations[n], abs=1e-9)


def test_more_sessions_shrink_the_shared_standard_errors(five):
    meas, cal = five.meas, five.cal
    first = cc.identify(five.nom, meas.take(meas.session == "S1"), PARAMETERS)
    assert first.sessions == {} and first.success
    for n in ("theta2", "a2", "d4", "theta5", "a6"):
        # five times the poses: about 1/√5 of the error, each session's frame aside
        assert 0.3 < cal.standard_errors[n] / first.standard_errors[n] < 0.6, n


def test_session_frames_are_named_and_always_estimated(five):
    cal = cc.identify(five.nom, five.meas, "theta*,a*,d*")  # the base not asked for
    assert cal.success, cal.message
    for label in ("S2", "S5"):
        names = [f"base_{a}@{label}" for a in ("x", "y", "z", "rx", "ry", "rz")]
        assert set(names) <= set(cal.estimated)
        assert cal.sessions[label].names == tuple(names)
    assert {"base_x", "base_rz"} <= set(cal.estimated)
    text = str(cal.summary())
    assert "5 sessions" in text and "estimated whatever the parameters" in text
    for label in ("S1", "S3", "S5"):
        assert f"\n{label} " in text  # a row of the sessions' table
    # the sessions' table in mm and degrees: S3's base x as fitted
    fit = cal.sessions["S3"]
    assert f"{fit.base.xyz[0] * 1e3:.4f} ± {fit.base_standard_errors[0] * 1e3:.4f}" in text
    assert f"{np.degrees(fit.base.rpy[2]):.4f}" in text


def test_one_session_column_gives_the_same_numbers_as_none():
    nom, _, _, meas = campaign(1, seed=3)
    plain = dataclasses.replace(meas, session=None)
    a = cc.identify(nom, plain, PARAMETERS)
    b = cc.identify(nom, meas, PARAMETERS)
    assert a.deviations == b.deviations
    np.testing.assert_array_equal(a.covariance, b.covariance)
    np.testing.assert_array_equal(a.residuals, b.residuals)
    assert a.robot == b.robot and b.sessions == {}
    assert str(a.summary()) == str(b.summary())


def test_per_session_tool_frames():
    """A probe re-mounted too: each session's tool position is its own."""
    rng = np.random.default_rng(5)
    nom = nominal()
    deviations = truth_deviations(rng)
    labels = ["A", "B", "C"]
    frames = frames_for(labels, rng)
    tools = {
        label: Frame(tuple(np.add(nom.tool.xyz, rng.normal(0, 2e-3, 3))), nom.tool.rpy)
        for label in labels
    }
    q = cc.poses.uniform(nom, 150, seed=6)
    meas = cc.simulate(
        nom.with_deviations(deviations),
        q,
        5e-5,
        seed=7,
        session=np.repeat(labels, 50),
        frames=frames,
        tools=tools,
    )
    params = "theta*,a*,d*,base,tool_x,tool_y,tool_z"
    truth = dict(deviations)
    for label in labels:  # the tools' true positions, as deviations from the nominal tool
        mark = "" if label == "A" else f"@{label}"
        offset = np.subtract(tools[label].xyz, nom.tool.xyz)
        truth.update({f"tool_{a}{mark}": float(v) for a, v in zip("xyz", offset, strict=True)})
    cal = cc.identify(nom, meas, params, per_session=("base", "tool"), truth=truth)
    assert cal.success, cal.message
    assert {"tool_x@B", "tool_z@C"} <= set(cal.estimated)
    again = cc.identify(cal.nominal, meas, list(cal.parameters))  # keeps a tool per session
    assert again.estimated == cal.estimated
    # with one tool for all, the same data cannot be fitted to their noise
    shared = cc.identify(nom, meas, params)
    assert shared.rms > 3 * cal.rms
    for label, fit in cal.sessions.items():
        assert fit.tool is not None and fit.names[6:9] == tuple(
            f"tool_{a}{'' if label == 'A' else '@' + label}" for a in "xyz"
        )
        assert np.all(np.abs(chart_errors(fit.base, frames[label])[:3]) < 2e-4)
        # each tool position as far as the data see it: a6 and d6 are held, and every
        # session's tool x and z stand for themselves plus the shared a6 and d6
        for name, se in zip(fit.names[6:9], fit.tool_standard_errors[:3], strict=True):
            assert np.isfinite(se) and se == cal.standard_errors[name]
            z = (cal.deviations[name] - cal.true_value(name)) / se
            assert abs(z) < 4, (name, cal.stands_for(name), z)


def test_validation_on_new_sessions(five):
    nom, deviations, cal = five.nom, five.deviations, five.cal
    rng = np.random.default_rng(99)
    q = cc.poses.uniform(nom, 60, seed=8)
    held = cc.simulate(
        nom.with_deviations(deviations),
        q,
        5e-5,
        seed=9,
        session=np.repeat(["X", "Y"], 30),
        frames=frames_for(["X", "Y"], rng),
    )
    v = cc.validate(cal.robot, held, nom)
    assert v.after.rms < 0.15e-3 < v.before.rms


def test_cross_validation_predicts_each_session_in_its_own_frame(five):
    """`compare_models` predicts held-out poses through their session's fitted frames:
    the noise (√3 σ = 0.087 mm), not the metres between the instruments."""
    meas = five.meas.take(np.arange(0, 250, 2))  # 25 poses a session, to keep it quick
    table = cc.compare_models({"rigid": five.nom}, meas, PARAMETERS, folds=3).table
    assert 0.07 < table["cv_rms_mm"].iloc[0] < 0.12
    cal = five.cal
    with pytest.raises(cc.CalibrationError, match="no session 'X'"):
        cal.session_robot("X")
    seen = cal.session_robot("S4").measured_points(five.meas.q[150:200])[:, 0]
    assert np.sqrt(np.mean(np.sum((seen - five.meas.positions[150:200]) ** 2, axis=1))) < 1e-4


# --- refusals --------------------------------------------------------------------------


@pytest.mark.parametrize("label", ["day 1", "a@b", "x.y", "", "a,b", "s*"])
def test_labels_that_cannot_make_names_are_refused(label):
    with pytest.raises(cc.CalibrationError, match="session label"):
        cc.Measurements(np.zeros((4, 6)), np.zeros((4, 3)), 0.0, session=["A", "A", label, "A"])


def test_sessions_need_their_poses_and_frames_their_sessions():
    nom, _, _, meas = campaign(2, seed=1, per_session=10)
    few = meas.take(np.r_[0:10, 10:12])
    with pytest.raises(cc.CalibrationError, match="session 'S2' has 2 poses"):
        cc.identify(nom, few, PARAMETERS)
    with pytest.raises(cc.CalibrationError, match="per_session"):
        cc.identify(nom, meas, PARAMETERS, per_session=("tool",))
    with pytest.raises(cc.CalibrationError, match="names session 'Z'"):
        cc.simulate(nom, meas.q, session=meas.session, frames={"Z": Frame()})
    with pytest.raises(cc.CalibrationError, match="one label per pose"):
        cc.Measurements(meas.q, meas.positions, 0.0, session="S1")
    with pytest.raises(cc.CalibrationError, match="bounds and priors on the base"):
        cc.identify(nom, meas, PARAMETERS, "ipopt", bounds={"base_x@S2": (-1, 1)})


# --- the model: exact Jacobian, exact per-session frames ------------------------------


def test_session_frame_columns_are_exact():
    """The graph's frame of a pose is its session's, bit for bit as computed by a plain
    robot, and its Jacobian columns are central differences of plain robots."""
    nom = nominal()
    B = Frame((1.5, -0.4, 0.3), (0.3, -0.5, 2.0))
    C = Frame((-2.0, 1.0, -0.2), (-0.2, 0.4, -1.0))
    robot = nom.with_sessions(["B", "C"]).with_parameters(
        {f"base_{a}@{lab}": v for lab, f in (("B", B), ("C", C)) for a, v in _items(f)}
    )
    q = cc.poses.uniform(nom, 9, seed=2)
    e = np.zeros((9, 2))
    e[3:6, 0] = 1.0  # poses 3-5 in session B, 6-8 in C, 0-2 in the first
    e[6:, 1] = 1.0
    qe = np.hstack([q, e])
    got = robot.position(qe)
    for rows, frame in ((slice(0, 3), nom.base), (slice(3, 6), B), (slice(6, 9), C)):
        plain = dataclasses.replace(nom, base=frame)
        np.testing.assert_allclose(got[rows], plain.position(q[rows]), rtol=0, atol=1e-13)
    names = [f"base_{a}@B" for a in ("x", "y", "z", "rx", "ry", "rz")]
    J, _ = robot.position_jacobian(qe, names)
    assert np.all(J[:3] == 0) and np.all(J[6:] == 0)  # other sessions' poses: exactly zero
    h = 1e-6
    values = np.array([*B.xyz, *B.rpy])
    for k in range(6):
        up, down = values.copy(), values.copy()
        up[k] += h
        down[k] -= h
        moved = [
            dataclasses.replace(nom, base=Frame(tuple(v[:3]), tuple(v[3:]))).position(q[3:6])
            for v in (up, down)
        ]
        np.testing.assert_allclose(J[3:6, :, k], (moved[0] - moved[1]) / (2 * h), atol=2e-8)


def _items(frame: Frame):
    return zip(("x", "y", "z", "rx", "ry", "rz"), (*frame.xyz, *frame.rpy), strict=True)


# --- files and the command line ---------------------------------------------------------


def test_csv_round_trip_with_sessions(tmp_path):
    nom, _, _, meas = campaign(3, seed=2, per_session=8)
    path = tmp_path / "m.csv"
    cc.write_csv(path, meas, nom)
    assert path.read_text().splitlines()[1].startswith("S1,")
    back = cc.read_csv(path, nom)
    assert back.sessions == ("S1", "S2", "S3")
    np.testing.assert_array_equal(back.session, meas.session)
    np.testing.assert_allclose(back.positions, meas.positions, rtol=0, atol=1e-12)
    np.testing.assert_allclose(back.q, meas.q, rtol=0, atol=1e-14)


def test_csv_session_labels_are_text_and_blank_cells_are_refused(tmp_path):
    nom = nominal()
    q = cc.poses.uniform(nom, 4, seed=1)
    meas = cc.simulate(nom, q)
    path = tmp_path / "m.csv"
    cc.write_csv(path, meas, nom)
    lines = path.read_text().splitlines()
    labels = ["1", "01", "1", "01"]
    rows = [f"{r},{s}" for r, s in zip(lines[1:], labels, strict=True)]
    numbered = [lines[0] + ",session", *rows]
    path.write_text("\n".join(numbered) + "\n")
    assert cc.read_csv(path, nom).sessions == ("1", "01")  # text: 1 and 01 differ
    blank = [*numbered[:3], numbered[3].rsplit(",", 1)[0] + ",", *numbered[4:]]
    path.write_text("\n".join(blank) + "\n")
    with pytest.raises(cc.CalibrationError, match="row 4, column 'session' is blank"):
        cc.read_csv(path, nom)
    spaced = [*numbered[:2], numbered[2].rsplit(",", 1)[0] + ",day 2", *numbered[3:]]
    path.write_text("\n".join(spaced) + "\n")
    with pytest.raises(cc.CalibrationError, match="row 3, column 'session'"):
        cc.read_csv(path, nom)


def test_cli_identify_prints_the_sessions(tmp_path):
    nom, _, _, meas = campaign(3, seed=4, per_session=40)
    robot = tmp_path / "nominal.toml"
    cc.save_robot(nom, robot)
    data = tmp_path / "m.csv"
    cc.write_csv(data, meas, nom)
    args = ["identify", str(robot), str(data), "--parameters", PARAMETERS]
    run = subprocess.run(
        [sys.executable, "-m", "casecal", *args, "-o", str(tmp_path / "cal.toml")],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin", "HOME": str(tmp_path)}
        | _cache_env(),
        timeout=300,
    )
    assert run.returncode == 0, run.stderr
    assert "Frames of the 3 measurement sessions" in run.stdout
    cal = cc.identify(nom, meas, PARAMETERS)
    for label in ("S1", "S2", "S3"):
        fit = cal.sessions[label]
        row = next(r for r in run.stdout.splitlines() if r.startswith(label + " "))
        assert f"{fit.base.xyz[1] * 1e3:.4f}" in row
        assert f"{np.degrees(fit.base.rpy[0]):.4f}" in row
    written = cc.load_robot(str(tmp_path / "cal.toml"))
    np.testing.assert_allclose(written.base.xyz, cal.sessions["S1"].base.xyz, atol=1e-9)


def _cache_env() -> dict:
    import os

    keep = ("CASECAL_CACHE", "CASECAL_BACKEND")
    return {k: os.environ[k] for k in keep if k in os.environ}


# --- Monte Carlo: standard errors that shrink with sessions and match the spread --------


@pytest.mark.slow
def test_monte_carlo_sessions_shrink_errors_that_match_the_spread():
    seeds = range(24)
    watched = ("theta2", "a2", "a3", "d4", "theta5", "a6")
    mean_se, spread, ratio = {}, {}, {}
    for count in range(1, 6):
        se, z = {n: [] for n in watched}, []
        error = {n: [] for n in watched}
        for seed in seeds:
            nom, deviations, _, meas = campaign(count, seed=1000 * count + seed)
            if count == 1:
                meas = dataclasses.replace(meas, session=None)
            cal = cc.identify(nom, meas, PARAMETERS, truth=deviations)
            assert cal.success, (count, seed, cal.message)
            for n in watched:
                assert cal.stands_for(n) == n or count == 1
                se[n].append(cal.standard_errors[n])
                error[n].append(cal.deviations[n] - cal.true_value(n))
            shared = [n for n in cal.estimated if not n.startswith("base_")]
            z += [(cal.deviations[n] - cal.true_value(n)) / cal.standard_errors[n] for n in shared]
        mean_se[count] = {n: float(np.mean(v)) for n, v in se.items()}
        spread[count] = float(np.std(z))  # every shared estimate of every seed, pooled
        ratio[count] = {n: float(np.std(error[n]) / np.mean(se[n])) for n in watched}
    for n in watched:
        values = [mean_se[c][n] for c in range(1, 6)]
        assert all(b < a for a, b in itertools.pairwise(values)), (n, values)
        # five times the poses: about 1/√5 of the error (0.43 measured)
        assert 0.35 < values[-1] / values[0] < 0.55, (n, values)
    for count, s in spread.items():
        assert 1 / 1.3 < s < 1.3, (count, s)
        # each parameter alone: 24 seeds know a spread to ±15 %, so ±3 of that
        assert all(1 / 1.5 < r < 1.5 for r in ratio[count].values()), (count, ratio[count])


def test_a_session_fits_nominal_and_predictions_serve_new_poses(five):
    """`cal.nominal` carries the sessions' frames: `validate` with it, and the predicted
    error at new poses, work in the first session's frame (they refused 'base_x@…')."""
    from casecal.design.campaign import calibrate_until, pool_measure, predicted_error

    nom, deviations, cal = five.nom, five.deviations, five.cal
    q = cc.poses.uniform(nom, 40, seed=8)
    held = cc.simulate(nom.with_deviations(deviations), q, 5e-5, seed=9)
    assert cc.validate(cal.robot, held, cal.nominal) == cc.validate(cal.robot, held, nom)
    assert 0 < predicted_error(cal, q) < 1e-3
    _, measure = pool_measure(five.meas)
    with pytest.raises(cc.CalibrationError, match="several sessions"):
        calibrate_until(nom, measure, candidates=five.meas.q, order="uniform")
