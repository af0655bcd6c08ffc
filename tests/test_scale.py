"""Identification at scale: memory that does not grow with the pose count, answers that do
not change when the Jacobian is streamed in batches, threads that stay out of each other's
way. Nothing here is timed (benchmarks/bench_scale.py measures speed)."""

from __future__ import annotations

import tracemalloc
from pathlib import Path

import numpy as np
import pytest

import casecal as cc
from casecal._threads import thread_map
from casecal.identification import problem as problem_module
from casecal.identification.linalg import Reduction


def _peak_bytes(robot, n: int) -> int:
    """Peak bytes allocated (numpy and Python) during `identify` of n poses, "all"."""
    q = cc.poses.uniform(robot, n, seed=0)
    meas = cc.simulate(robot.with_deviations({"a2": 1e-4, "d3": -2e-4}), q, noise=2e-5, seed=1)
    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        cal = cc.identify(robot, meas, "all")
        peak = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
    assert cal.success, cal.message
    return peak


def test_peak_memory_grows_like_the_measurements_not_the_jacobian():
    robot = cc.load_robot("puma560")
    _peak_bytes(robot, 2000)  # kernels loaded, caches warm
    small, large = 16000, 64000
    per_pose = (_peak_bytes(robot, large) - _peak_bytes(robot, small)) / (large - small)
    k = len(robot.parameter_names)
    jacobian = 3 * k * 8  # one whole Jacobian, B per pose (888 for the PUMA's 37)
    inputs = (6 + 3 + 3) * 8  # joint values, measured point and its sigma, B per pose
    # residuals, weights and the memoised points are each the size of the measured
    # points; the Jacobian itself never exists whole (before: 4 copies, 3.5 kB/pose)
    assert per_pose <= 5 * inputs, (per_pose, inputs)
    assert per_pose < 0.6 * jacobian, (per_pose, jacobian)


@pytest.fixture
def tiny_batches(monkeypatch):
    monkeypatch.setattr(problem_module, "BATCH_POSES", 7)


def test_streamed_fit_equals_one_batch(tiny_batches):
    """The same fit whether the Jacobian is folded 7 poses at a time or whole."""
    robot = cc.load_robot("puma560")
    q = cc.poses.uniform(robot, 300, seed=3)
    truth = {"a2": 2e-4, "d3": -1e-4, "alpha3": 3e-4, "theta4": -2e-4}
    meas = cc.simulate(robot.with_deviations(truth), q, noise=2e-5, seed=4)
    streamed = cc.identify(robot, meas, ["theta*", "a*", "d*", "alpha*"])
    problem_module.BATCH_POSES = 10**9
    whole = cc.identify(robot, meas, ["theta*", "a*", "d*", "alpha*"])
    assert streamed.success and whole.success
    assert streamed.estimated == whole.estimated
    for name in whole.estimated:
        assert streamed.deviations[name] == pytest.approx(whole.deviations[name], abs=1e-12)
        assert streamed.standard_errors[name] == pytest.approx(
            whole.standard_errors[name], rel=1e-9
        )


def test_memo_keeps_the_latest_used_of_each_size(monkeypatch):
    """Evaluations (O(N) arrays) and reductions (small) are evicted each within their own
    budget, least recently used first: the fit's start must survive its solver's steps."""
    monkeypatch.setattr(problem_module, "MEMO", 3)
    monkeypatch.setattr(problem_module, "MEMO_SMALL", 2)
    robot = cc.load_robot("puma560")
    q = cc.poses.uniform(robot, 5, seed=0)
    problem = problem_module.Problem(robot, q, np.zeros((5, 3)), np.ones((5, 3)), ["a2"])
    points = np.zeros((5, 3))  # the size of the measured points: the budget's unit
    for i in range(3):
        problem._memoised(("points", i), lambda: points.copy())
    problem._memoised(("reduced", 0), lambda: "small")
    problem._memoised(("points", 0), lambda: pytest.fail("evicted"))  # used again: latest
    for i in range(3, 5):
        problem._memoised(("points", i), lambda: points.copy())
    problem._memoised(("reduced", 1), lambda: "small")
    assert sorted(k for k in problem._memo if k[0] == "points") == [
        ("points", 0),
        ("points", 3),
        ("points", 4),
    ]
    assert sorted(k for k in problem._memo if k[0] == "reduced") == [("reduced", 0), ("reduced", 1)]
    problem._memoised(("fk", 0), lambda: np.zeros((5, 4, 4)))  # 16/3 times as large
    assert sorted(k for k in problem._memo if k[0] != "reduced") == [("fk", 0)]


def test_a_shared_memo_never_mixes_data():
    """Problems that share a memo but not their data arrays meet in none of its keys."""
    robot = cc.load_robot("puma560")
    q = cc.poses.uniform(robot, 40, seed=0)
    y = robot.position(q) + 1e-4
    memo: dict = {}
    x = np.zeros(2)

    def make(q, y, w):
        return problem_module.Problem(robot, q, y, w, ["a2", "d3"], memo=memo)

    one = make(q, y, np.ones((40, 3)))
    assert one.reduced(x).rr == pytest.approx(3 * 40 * 1e-8)
    other_weights = make(q, y, np.full((40, 3), 10.0))
    assert other_weights.reduced(x).rr == pytest.approx(3 * 40 * 1e-6)
    q2 = q.copy()
    q2[:, 1] += 0.1
    other_poses = make(q2, y, np.ones((40, 3)))
    assert np.abs(other_poses.residual(x)).max() > 1e-2  # not the first poses' points


def test_a_residual_ahead_brings_the_normal_equations_of_its_point(tiny_batches):
    """One pass of points and Jacobian gives the residual and the normal equations that
    separate passes give, and the solver's next step finds them without a pass."""
    robot = cc.load_robot("puma560").with_points([[0.02, 0.01, 0.08], [0.0, 0.05, 0.1]])
    q = cc.poses.uniform(robot, 60, seed=5)
    meas = cc.simulate(robot.with_deviations({"a2": 2e-4, "alpha3": 1e-4}), q, noise=2e-5)
    names = ["a2", "d3", "alpha3", "theta4"]
    w = np.full((60, 3), 1 / 2e-5)

    def fresh():
        return problem_module.Problem(robot, q, meas.positions, w, names)

    x = np.array([1e-4, -2e-4, 5e-5, 1e-4])
    ahead, plain = fresh(), fresh()
    r_ahead, r_plain = ahead.residual(x, ahead=True), plain.residual(x)
    assert np.array_equal(r_ahead, r_plain)
    ahead._runs = lambda *a: pytest.fail("a second pass over the poses")
    step = ahead.reduced(x, r_ahead, exact=False)
    plain_step = plain.reduced(x, r_plain, exact=False)
    assert np.array_equal(step.R, plain_step.R) and np.array_equal(step.Qtr, plain_step.Qtr)


def test_a_qr_pass_rounds_the_same_on_any_number_of_cores(tiny_batches, monkeypatch):
    robot = cc.load_robot("puma560")
    q = cc.poses.uniform(robot, 200, seed=6)
    meas = cc.simulate(robot.with_deviations({"a2": 2e-4}), q, noise=2e-5, seed=7)
    problem = problem_module.Problem(
        robot, q, meas.positions, np.full((200, 3), 5e4), robot.parameter_names
    )
    x = np.zeros(len(robot.parameter_names))
    r, p = problem.residual(x), problem.p(x)
    from casecal import _threads

    folds = []
    for threads in (1, 2, 3):  # the pool is used even where the machine has one core
        monkeypatch.setattr(_threads, "cores", lambda threads=threads: threads)
        folds.append(problem._reduce(p, r))
    for other in folds[1:]:
        assert np.array_equal(other.R, folds[0].R) and np.array_equal(other.Qtr, folds[0].Qtr)
    whole = Reduction.of(problem.jacobian(x), r)
    s_whole = np.linalg.svd(whole.R, compute_uv=False)
    assert np.linalg.svd(folds[0].R, compute_uv=False) == pytest.approx(
        s_whole, rel=1e-9, abs=1e-9 * s_whole[0]
    )


@pytest.mark.parametrize("weights", ["one sigma", "per axis", "reweighted"])
def test_passes_hold_the_weighted_system_whatever_the_weights(tiny_batches, weights):
    """The QR pass and the normal equations (which leave rows of one shared weight
    unweighted and scale what they sum) hold the system of the explicitly weighted
    Jacobian: ``RᵀR = JᵀJ``, ``Rᵀ Qᵀr = Jᵀr``, ``G = JᵀJ``, ``g = Jᵀr``."""
    robot = cc.load_robot("puma560")
    q = cc.poses.uniform(robot, 90, seed=8)
    meas = cc.simulate(robot.with_deviations({"a2": 2e-4, "d3": 1e-4}), q, noise=2e-5, seed=9)
    w = np.full((90, 3), 1 / 2e-5)
    if weights == "per axis":
        w = w * [1.0, 2.0, 0.5]
    names = ["a2", "d3", "alpha3", "theta4", "a3"]
    problem = problem_module.Problem(robot, q, meas.positions, w, names)
    if weights == "reweighted":
        problem = problem.reweighted(np.linspace(0.2, 1.0, 90)[:, None])
    assert (problem._uniform is not None) == (weights == "one sigma")
    x = np.array([1e-4, -2e-4, 5e-5, 1e-4, 3e-5])
    r, J = problem.residual(x), problem.jacobian(x)  # J: every row weighted by hand
    red = problem._reduce(problem.p(x), r)
    JtJ, Jtr = J.T @ J, J.T @ r
    scale = np.abs(JtJ).max()
    assert np.abs(red.R.T @ red.R - JtJ).max() < 1e-12 * scale
    assert np.abs(red.R.T @ red.Qtr - Jtr).max() < 1e-12 * np.sqrt(scale * (r @ r))
    G, g = problem._normal(problem.p(x), r)
    assert np.abs(G - JtJ).max() < 1e-12 * scale
    assert np.abs(g - Jtr).max() < 1e-12 * np.sqrt(scale * (r @ r))


def test_reduction_keeps_what_the_tall_system_holds():
    """Folded in pieces, R and Qᵀr give lstsq's answer, the residual and the singular
    values of the tall system, also for a blind (rank-deficient) column pair."""
    rng = np.random.default_rng(0)
    J = rng.normal(size=(500, 6)) * [1.0, 1e3, 1e-3, 1.0, 1.0, 1.0]
    J[:, 5] = 2.0 * J[:, 0]  # blind: only theta-like column 0 + 2 * column 5 is seen
    r = rng.normal(size=500)
    red = Reduction.of(J[:123], r[:123]).merge(Reduction.of(J[123:400], r[123:400]))
    red = red.fold(J[400:], r[400:])
    assert red.rows == 500 and red.rr == pytest.approx(r @ r)
    s_tall = np.linalg.svd(J, compute_uv=False)
    s_red = np.linalg.svd(red.R, compute_uv=False)
    assert s_red[:5] == pytest.approx(s_tall[:5], rel=1e-12)
    assert s_red[5] < 1e-12 * s_red[0]  # the blind direction stays at rounding
    x = np.linalg.lstsq(J, r, rcond=1e-12)[0]
    step, decrease = red.solve()
    assert J @ step == pytest.approx(J @ x, abs=1e-9)
    rest = r - J @ x
    assert decrease == pytest.approx(0.5 * (r @ r - rest @ rest), rel=1e-9)
    sub = red.columns([1, 3])
    x13 = np.linalg.lstsq(J[:, [1, 3]], r, rcond=None)[0]
    assert sub.solve()[0] == pytest.approx(x13, rel=1e-10)


def test_thread_map_keeps_order_and_does_not_deadlock_when_nested():
    def inner(i):
        return sum(thread_map(lambda j: i * j, list(range(5))))

    assert thread_map(inner, list(range(8))) == [10 * i for i in range(8)]


def test_kernels_write_into_a_given_buffer():
    from casecal.model import kinematics

    robot = cc.load_robot("puma560")
    chain = kinematics.chain(robot.structure)
    q = cc.poses.uniform(robot, 300, seed=2)
    cols = chain.columns(("a2", "d3", "alpha4"))
    fresh = chain.evaluate("points_jacobian", q, robot.vector(), cols)
    out = np.full((300, 3, 3), np.nan)
    got = chain.evaluate("points_jacobian", q, robot.vector(), cols, out)
    assert got is out and np.array_equal(out, fresh)
    with pytest.raises(ValueError, match="shape"):
        chain.evaluate("points_jacobian", q, robot.vector(), cols, np.empty((300, 3, 4)))
    with pytest.raises(ValueError, match="float64"):  # C would write past its end
        chain.evaluate("points_jacobian", q, robot.vector(), cols, np.empty((300, 3, 3), "f4"))


def _robots_for_backends():
    from test_terms import MARKER, heavy

    examples = Path(__file__).parents[1] / "examples"
    return {
        "dh": cc.load_robot("puma560"),
        "mdh-points": cc.load_robot("rx90b_mdh").with_points(MARKER),
        "dh-compliance-harmonics": heavy().with_compliance([2, 3]).with_joint_harmonics(2, 2),
        "urdf-lumped": cc.load_robot(examples / "kr16_2.urdf").with_compliance([2, 3]),
        "prismatic": cc.load_robot("scara"),
    }


@pytest.mark.parametrize("name", list(_robots_for_backends()))
def test_numpy_evaluation_without_a_compiler_equals_casadi(name, monkeypatch):
    """The instruction list run by numpy over all poses gives CasADi's numbers, for every
    output the identification uses."""
    from casecal.model import kinematics

    robot = _robots_for_backends()[name]
    robot = robot.with_deviations({n: 1e-4 for n in robot.parameter_names[:5]})
    q = cc.poses.uniform(robot, 300, seed=1)
    chain = kinematics.chain(robot.structure)
    every = chain.columns(None)
    for kind in ("fk", "points", "points_jacobian", "pose_jacobian"):
        columns = every if kind.endswith("jacobian") else ()
        monkeypatch.setenv("CASECAL_BACKEND", "casadi")
        reference = chain._evaluator(kind, columns)(q, chain.extended(robot.vector()))
        monkeypatch.setenv("CASECAL_BACKEND", "numpy")
        got = kinematics.Evaluator(chain, kind, columns)(q, chain.extended(robot.vector()))
        assert got.shape == reference.shape
        np.testing.assert_allclose(got, reference, rtol=1e-13, atol=1e-15, err_msg=kind)


def test_identify_without_a_compiler_gives_the_compiled_answer(monkeypatch):
    robot = cc.load_robot("puma560")
    q = cc.poses.uniform(robot, 400, seed=5)
    meas = cc.simulate(robot.with_deviations({"a2": 2e-4, "d3": -1e-4}), q, noise=2e-5, seed=6)
    from casecal.model import _native, kinematics

    # auto would answer by numpy until compiling pays (tests/test_deferred_compile.py)
    monkeypatch.setenv("CASECAL_BACKEND", "c" if _native.compiler() else "auto")
    compiled = cc.identify(robot, meas, ["theta*", "a*", "d*", "alpha*"])
    monkeypatch.setenv("CASECAL_BACKEND", "numpy")

    kinematics.chain.cache_clear()  # evaluators are made anew under the numpy backend
    vectorised = cc.identify(robot, meas, ["theta*", "a*", "d*", "alpha*"])
    kinematics.chain.cache_clear()
    assert vectorised.success and vectorised.estimated == compiled.estimated
    for name in compiled.estimated:
        assert vectorised.deviations[name] == pytest.approx(compiled.deviations[name], abs=1e-12)


def test_a_mistyped_backend_is_refused_not_taken_for_auto(monkeypatch):
    robot = cc.load_robot("puma560")
    q = cc.poses.uniform(robot, 300, seed=0)
    monkeypatch.setenv("CASECAL_BACKEND", "nunpy")
    with pytest.raises(cc.CalibrationError, match="CASECAL_BACKEND='nunpy'"):
        robot.position(q)
