"""A damaged kernel cache is repaired, never a crash (issue 10).

A truncated library gave SIGBUS, one without the symbol an AttributeError, kernels swapped
between files SIGSEGV, flipped bytes SIGILL, and the cache stayed broken. Each case runs in
a new process (a loaded library stays loaded for the life of a process).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time

import numpy as np
import pytest

pytestmark = pytest.mark.skipif(
    shutil.which("cc") is None and shutil.which("gcc") is None,
    reason="no C compiler: no kernel cache to damage",
)

PROBE = """
import numpy as np, casecal as cc
from casecal.model import _evaluate  # no budget: auto compiles at the first batch (issue 23)
_evaluate.COMPILE_SECONDS_BASE = _evaluate.COMPILE_SECONDS_PER_INSTRUCTION = 0.0
r = cc.load_robot("puma560")
q = cc.poses.uniform(r, 400, seed=0)
J, _ = r.position_jacobian(q, ["theta*", "a*"])
np.save(OUT, np.concatenate([r.position(q).ravel(), J.ravel()]))
"""


def probe(cache, out):
    env = {**os.environ, "CASECAL_CACHE": str(cache), "CASECAL_BACKEND": "auto"}
    code = PROBE.replace("OUT", repr(str(out)))
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    return done.returncode, done.stderr, (np.load(out) if done.returncode == 0 else None)


def libraries(cache):
    return sorted(cache.glob("casecal_*.so"))


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    cache = tmp_path_factory.mktemp("cache")
    code, err, values = probe(cache, cache / "ref.npy")
    assert code == 0, err
    assert len(libraries(cache)) >= 2  # positions and their Jacobian
    return cache, values


def damaged(reference, tmp_path, how):
    source, values = reference
    cache = tmp_path / "cache"
    shutil.copytree(source, cache)
    a, b = libraries(cache)[:2]
    how(cache, a, b)
    code, err, got = probe(cache, tmp_path / "out.npy")
    return code, err, got, values, cache


def truncate(cache, a, b):
    data = a.read_bytes()
    a.write_bytes(data[: len(data) // 2])


def flip(cache, a, b):
    data = bytearray(a.read_bytes())
    for k in range(1000, len(data), 997):
        data[k] ^= 0xFF
    a.write_bytes(bytes(data))


def swap_libraries(cache, a, b):
    da, db = a.read_bytes(), b.read_bytes()
    a.write_bytes(db)
    b.write_bytes(da)


def swap_with_records(cache, a, b):
    swap_libraries(cache, a, b)
    ra, rb = a.with_suffix(".json"), b.with_suffix(".json")
    ta, tb = ra.read_text(), rb.read_text()
    ra.write_text(tb)
    rb.write_text(ta)


def no_record(cache, a, b):
    a.with_suffix(".json").unlink()


def no_symbol(cache, a, b):
    src = cache / "x.c"
    src.write_text("int unrelated(void) { return 1; }\n")
    cc = shutil.which("cc") or shutil.which("gcc")
    subprocess.run([cc, "-shared", "-fPIC", str(src), "-o", str(a)], check=True)
    data = a.read_bytes()
    record = {"size": len(data), "sha256": __import__("hashlib").sha256(data).hexdigest()}
    a.with_suffix(".json").write_text(json.dumps(record))


@pytest.mark.slow
@pytest.mark.parametrize(
    "how", [truncate, flip, swap_libraries, swap_with_records, no_record, no_symbol]
)
def test_damaged_kernels_are_rebuilt_with_one_warning(reference, tmp_path, how):
    code, err, got, values, cache = damaged(reference, tmp_path, how)
    assert code == 0, err
    np.testing.assert_allclose(got, values, rtol=0, atol=1e-15)
    # one line per damaged file (a swap damages two), nothing else on stderr
    files = 2 if how.__name__.startswith("swap") else 1
    lines = err.splitlines()
    assert len(lines) == files and all("damaged" in x and "rebuilding" in x for x in lines), err
    # and the cache is whole again: the next run says nothing
    code, err, got = probe(cache, tmp_path / "again.npy")
    assert code == 0 and "damaged" not in err
    np.testing.assert_allclose(got, values, rtol=0, atol=1e-15)


@pytest.mark.slow
def test_a_killed_compiles_build_folder_is_swept(reference, tmp_path):
    cache = tmp_path / "cache"
    stale = cache / "casecal-build-left-by-a-kill"
    stale.mkdir(parents=True)
    (stale / "kernel.c").write_text("/* half written */")
    old = time.time() - 2 * 3600
    os.utime(stale, (old, old))
    code, err, _ = probe(cache, tmp_path / "out.npy")  # empty cache: builds, and sweeps
    assert code == 0, err
    assert not stale.exists()
