"""The numpy evaluator's code cached on disk (`casecal.model._numpy_cache`).

A warm process loads what an earlier one translated and compiled, builds no CasADi graph,
and gets the same bits. Every kind of damaged entry evaluates right and is repaired; what
is not ours in an entry's place is left alone. Each case runs in new processes: an
evaluator, once loaded, stays loaded in a process.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

PROBE = """
import sys, numpy as np, casecal as cc
from casecal.model import _evaluate, kinematics
if sys.argv[2] == "warm":  # a warm process must not build any graph or Function
    def refuse(*args, **kwargs):
        raise AssertionError("a CasADi graph was built")
    kinematics.Chain._build = kinematics.Chain.function = refuse
# auto: every Function counts as too long for the compiler (an elastic humanoid's Jacobian)
_evaluate.COMPILE_MAX_INSTRUCTIONS = 0
r = cc.load_robot("puma560")
q = cc.poses.uniform(r, 300, seed=0)
J, _ = r.position_jacobian(q, ["theta*", "a*"])
np.save(sys.argv[1], np.concatenate([r.position(q).ravel(), J.ravel()]))
"""


def probe(cache, out, warm: bool, backend: str = "numpy"):
    env = {**os.environ, "CASECAL_CACHE": str(cache), "CASECAL_BACKEND": backend}
    done = subprocess.run(
        [sys.executable, "-c", PROBE, str(out), "warm" if warm else "cold"],
        env=env,
        capture_output=True,
        text=True,
    )
    return done.returncode, done.stderr, (np.load(out) if done.returncode == 0 else None)


@pytest.fixture(scope="module")
def good(tmp_path_factory):
    """A cache folder holding the PUMA's two numpy evaluators, and their values."""
    cache = tmp_path_factory.mktemp("cache")
    code, err, values = probe(cache, cache.parent / "cold.npy", warm=False)
    assert code == 0, err
    entries = sorted(cache.glob("casecal_*.numpy"))
    assert len(entries) == 2, list(cache.iterdir())
    assert not list(cache.glob("casecal-build-*"))  # no temporary folder left
    return cache, values


@pytest.mark.parametrize("backend", ["numpy", "auto"])
def test_a_warm_process_builds_no_graph_and_gets_the_same_bits(good, tmp_path, backend):
    cache, values = good
    code, err, warm = probe(cache, tmp_path / "warm.npy", warm=True, backend=backend)
    assert code == 0, err
    assert np.array_equal(warm, values)
    assert not list(cache.glob("casecal_*.so"))  # auto compiled nothing: numpy answered


def test_the_cached_values_are_casadis(good, tmp_path):
    """The translated code against CasADi's own evaluation of the same Functions."""
    _, values = good
    code, err, casadi = probe(tmp_path / "empty", tmp_path / "casadi.npy", False, "casadi")
    assert code == 0, err
    assert np.allclose(values, casadi, rtol=0, atol=1e-12)


def _header(path):
    head, _, payload = path.read_bytes().partition(b"\n")
    return json.loads(head), payload


def _write(path, record, payload):
    path.write_bytes(json.dumps(record).encode() + b"\n" + payload)


def truncated(path, other):
    path.write_bytes(path.read_bytes()[:-100])


def flipped(path, other):
    record, payload = _header(path)
    payload = bytearray(payload)
    payload[len(payload) // 2] ^= 0xFF
    _write(path, record, bytes(payload))


def resigned_garbage(path, other):
    """Bytes that are not code, with a header that matches them: marshal must not read
    what it cannot trust, and what it reads must be code."""
    import marshal
    import zlib

    from casecal.model._numpy_cache import _checksum

    record, _ = _header(path)
    payload = zlib.compress(marshal.dumps([1, 2, 3]))
    record["size"] = len(payload)
    record["sha256"] = _checksum(record, payload)
    _write(path, record, payload)


def edited_count(path, other):
    """The header's output count edited: the checksum covers it."""
    record, payload = _header(path)
    record["n_out"] += 1
    _write(path, record, payload)


def resigned_count(path, other):
    """A wrong output count that the checksum vouches for: the evaluator's own shape
    decides, not the header (a wrong count had raised in every process)."""
    from casecal.model._numpy_cache import _checksum

    record, payload = _header(path)
    record["n_out"] += 3
    record["sha256"] = _checksum(record, payload)
    _write(path, record, payload)


def swapped(path, other):
    """Another evaluator's entry under this one's name."""
    path.write_bytes(other.read_bytes())


def another_python(path, other):
    record, payload = _header(path)
    record["magic"] = "00000000"
    _write(path, record, payload)


def garbled_header(path, other):
    _, payload = _header(path)
    path.write_bytes(b'{"key": 1}\n' + payload)


def empty(path, other):
    path.write_bytes(b"")


def deeply_nested_header(path, other):
    """JSON nested deeper than the parser recurses."""
    _, payload = _header(path)
    path.write_bytes(b"[" * 100_000 + b"\n" + payload)


@pytest.mark.parametrize(
    "how",
    [
        truncated,
        flipped,
        resigned_garbage,
        edited_count,
        resigned_count,
        swapped,
        another_python,
        garbled_header,
        empty,
        deeply_nested_header,
    ],
    ids=lambda f: f.__name__,
)
def test_a_damaged_entry_evaluates_right_and_is_repaired(good, tmp_path, how):
    cache, values = good
    mine = tmp_path / "cache"
    mine.mkdir()
    first, second = sorted(cache.glob("casecal_*.numpy"))
    for entry in (first, second):
        (mine / entry.name).write_bytes(entry.read_bytes())
    how(mine / first.name, mine / second.name)
    code, err, got = probe(mine, tmp_path / "a.npy", warm=False)
    assert code == 0, err
    assert np.array_equal(got, values)
    assert "is damaged" in err and err.count("is damaged") == 1, err
    # repaired: the next process loads both entries without building anything
    code, err, got = probe(mine, tmp_path / "b.npy", warm=True)
    assert code == 0, err
    assert np.array_equal(got, values) and "damaged" not in err


def test_what_is_not_ours_in_an_entrys_place_is_left_alone(good, tmp_path):
    cache, values = good
    mine = tmp_path / "cache"
    mine.mkdir()
    first, second = sorted(cache.glob("casecal_*.numpy"))
    (mine / first.name).mkdir()
    (mine / first.name / "keep.txt").write_text("a user's file")
    os.mkfifo(mine / second.name)  # reading a FIFO would wait forever
    code, err, got = probe(mine, tmp_path / "a.npy", warm=False)
    assert code == 0, err
    assert np.array_equal(got, values)
    assert (mine / first.name / "keep.txt").read_text() == "a user's file"
    assert not (mine / second.name).is_file() and (mine / second.name).exists()
    assert err.count("is not a regular file") == 1, err  # said, once, not silent


def test_a_cache_that_cannot_be_written_costs_only_the_rebuild(good, tmp_path):
    _, values = good
    blocked = tmp_path / "file"
    blocked.write_text("a file where the cache folder would be")
    code, err, got = probe(blocked / "cache", tmp_path / "a.npy", warm=False)
    assert code == 0, err
    assert np.array_equal(got, values)
    assert "Traceback" not in err
