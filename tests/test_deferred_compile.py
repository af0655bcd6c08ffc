"""Answers before the compiler (issue 23): with backend "auto", a kernel that is not in the
disk cache is compiled only once numpy's seconds on its kind reach its compile time.

A first fit of 200 poses on an empty cache waited 3.5 s for GCC (numpy: 0.8 s). Now numpy
answers, with the same bits, until compiling pays (`casecal.model._evaluate` module doc).
"""

from __future__ import annotations

import threading

import numpy as np
import pytest

import casecal as cc
from casecal.model import _evaluate, _native, kinematics

pytestmark = pytest.mark.skipif(
    _native.compiler() is None, reason="no C compiler: nothing is ever compiled"
)


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """An empty kernel cache, backend "auto", and chains (with their evaluators) anew."""
    folder = tmp_path / "cache"
    monkeypatch.setenv("CASECAL_CACHE", str(folder))
    monkeypatch.setenv("CASECAL_BACKEND", "auto")
    kinematics.chain.cache_clear()
    yield folder
    kinematics.chain.cache_clear()


@pytest.fixture
def c_calls(monkeypatch):
    """Calls of compiled kernels, and builds of kernels, counted."""
    counts = {"calls": 0, "builds": 0}
    kernel, build = _native.kernel, _native._build

    def counting_kernel(*args, **kwargs):
        call = kernel(*args, **kwargs)
        if call is None:
            return None

        def counted(*a):
            counts["calls"] += 1
            return call(*a)

        return counted

    def counting_build(*args, **kwargs):
        counts["builds"] += 1
        return build(*args, **kwargs)

    monkeypatch.setattr(_native, "kernel", counting_kernel)
    monkeypatch.setattr(_native, "_build", counting_build)
    return counts


def kernels(folder):
    return sorted(folder.glob("casecal_*.so")) if folder.exists() else []


def tiny_budget(monkeypatch, seconds=1e-12):
    """Compiling pays after any numpy work at all (but not before it)."""
    monkeypatch.setattr(_evaluate, "COMPILE_SECONDS_BASE", seconds)
    monkeypatch.setattr(_evaluate, "COMPILE_SECONDS_PER_INSTRUCTION", 0.0)


def fit(n=200):
    robot = cc.load_robot("puma560")
    q = cc.poses.uniform(robot, n, seed=0)
    deviations = {"a2": 1e-4, "d3": -2e-4, "theta3": 1e-4}
    meas = cc.simulate(robot.with_deviations(deviations), q, noise=2e-5, seed=2)
    return cc.identify(robot, meas)


def test_a_first_fit_of_200_poses_compiles_nothing_and_gives_the_c_bits(
    cache, c_calls, monkeypatch
):
    numpy_fit = fit()
    assert kernels(cache) == [] and c_calls["builds"] == 0 and c_calls["calls"] == 0
    assert numpy_fit.success
    monkeypatch.setenv("CASECAL_BACKEND", "c")
    kinematics.chain.cache_clear()
    c_fit = fit()
    assert kernels(cache) and c_calls["calls"] > 0  # the same fit did run in C
    assert c_fit.estimated == numpy_fit.estimated
    for name in c_fit.estimated:  # numpy and C do the same arithmetic in the same order
        assert numpy_fit.deviations[name] == c_fit.deviations[name], name
        assert numpy_fit.standard_errors[name] == c_fit.standard_errors[name], name


def test_once_numpy_has_spent_the_compile_time_the_kernel_is_built_and_used(
    cache, c_calls, monkeypatch
):
    tiny_budget(monkeypatch)
    robot = cc.load_robot("puma560")
    q = cc.poses.uniform(robot, 250, seed=1)
    chain = kinematics.chain(robot.structure)
    first = robot.position_jacobian(q, ["a*"])[0]  # numpy, and its seconds counted
    assert kernels(cache) == [] and c_calls["calls"] == 0
    assert 0 < _evaluate.spent(chain, "position_jacobian") < np.inf
    second = robot.position_jacobian(q, ["a*"])[0]  # the account pays: compiled, then C
    assert len(kernels(cache)) == 1 and c_calls == {"calls": 1, "builds": 1}
    third = robot.position_jacobian(q, ["a*"])[0]
    assert c_calls == {"calls": 2, "builds": 1}
    assert np.array_equal(first, second) and np.array_equal(second, third)
    # the kind is hot: another column set compiles at its first batch
    robot.position_jacobian(q, ["d*"])
    assert len(kernels(cache)) == 2 and c_calls == {"calls": 3, "builds": 2}
    # another kind keeps its own account
    robot.position(q)
    assert len(kernels(cache)) == 2 and c_calls["calls"] == 3


def test_the_default_budget_is_the_estimated_compile_time(cache, c_calls):
    """Until numpy's seconds on a kind reach `compile_seconds` (a few tenths of a second
    for a PUMA's Jacobian), numpy answers; the seconds add up across column sets."""
    robot = cc.load_robot("puma560")
    q = cc.poses.uniform(robot, 200, seed=1)
    chain = kinematics.chain(robot.structure)
    robot.position_jacobian(q, ["a*"])
    robot.position_jacobian(q, ["d*"])
    evaluator = next(e for (k, _), e in chain._evaluators.items() if k == "position_jacobian")
    budget = _evaluate.compile_seconds(evaluator.function.n_instructions())
    assert 0.1 < budget < 2.0
    assert 0 < _evaluate.spent(chain, "position_jacobian") < budget
    assert kernels(cache) == [] and c_calls["calls"] == 0


def test_a_cached_kernel_is_used_at_once(cache, c_calls, monkeypatch):
    robot = cc.load_robot("puma560")
    q = cc.poses.uniform(robot, 200, seed=3)
    monkeypatch.setenv("CASECAL_BACKEND", "c")
    compiled = robot.position(q)
    assert len(kernels(cache)) == 1 and c_calls == {"calls": 1, "builds": 1}
    monkeypatch.setenv("CASECAL_BACKEND", "auto")
    kinematics.chain.cache_clear()  # a new process, as far as evaluators go
    again = robot.position(q)
    assert c_calls == {"calls": 2, "builds": 1}  # loaded, not rebuilt, and run
    assert _evaluate.spent(kinematics.chain(robot.structure), "position") == 0.0
    assert np.array_equal(compiled, again)


def test_backend_c_compiles_a_batch_of_200_poses(cache, c_calls, monkeypatch):
    monkeypatch.setenv("CASECAL_BACKEND", "c")
    robot = cc.load_robot("puma560")
    robot.position_jacobian(cc.poses.uniform(robot, 200, seed=4), ["theta*"])
    assert len(kernels(cache)) == 1 and c_calls == {"calls": 1, "builds": 1}


def test_a_large_batch_compiles_at_once(cache, c_calls, monkeypatch):
    monkeypatch.setattr(_evaluate, "COMPILE_LARGE_BATCH", 300)  # 20,000 poses, in small
    robot = cc.load_robot("puma560")
    robot.position(cc.poses.uniform(robot, 299, seed=5))
    assert kernels(cache) == [] and c_calls["calls"] == 0
    robot.position(cc.poses.uniform(robot, 300, seed=5))
    assert len(kernels(cache)) == 1 and c_calls == {"calls": 1, "builds": 1}


def test_small_batches_and_long_functions_spend_nothing_towards_a_kernel(
    cache, c_calls, monkeypatch
):
    robot = cc.load_robot("puma560")
    chain = kinematics.chain(robot.structure)
    robot.position(cc.poses.uniform(robot, 199, seed=6))  # CasADi's own: no account
    assert _evaluate.spent(chain, "position") == 0.0
    # a Function over COMPILE_MAX_INSTRUCTIONS still waits for a large batch
    tiny_budget(monkeypatch)
    monkeypatch.setattr(_evaluate, "COMPILE_MAX_INSTRUCTIONS", 10)
    q = cc.poses.uniform(robot, 200, seed=6)
    for _ in range(3):
        robot.position(q)
    assert kernels(cache) == [] and c_calls["calls"] == 0


def test_threads_reaching_the_budget_together_build_one_kernel(cache, c_calls, monkeypatch):
    tiny_budget(monkeypatch)
    robot = cc.load_robot("puma560")
    q = cc.poses.uniform(robot, 300, seed=7)
    reference = robot.position_jacobian(q, ["theta*"])[0]  # numpy: pays the budget
    results, errors = [], []
    start = threading.Barrier(4)

    def work():
        try:
            start.wait()
            for _ in range(5):
                results.append(robot.position_jacobian(q, ["theta*"])[0])
        except Exception as exc:  # reported below
            errors.append(exc)

    threads = [threading.Thread(target=work) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []
    assert len(kernels(cache)) == 1 and c_calls["builds"] == 1 and c_calls["calls"] == 20
    assert all(np.array_equal(r, reference) for r in results)
