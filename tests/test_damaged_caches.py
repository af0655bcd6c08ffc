"""Every kind of damaged kernel cache still evaluates right, and is repaired (issue 20).

Findings 11 and 16: a sidecar holding valid JSON that is not an object gave an
AttributeError on every later run; a re-signed damaged library a UnicodeDecodeError; a
read-only cache warned once per kernel; ``CASECAL_CACHE=.`` fell back to numpy with a
dlopen message. One small kernel (the rr robot's positions, compiled in well under a
second) is built once; each case copies it into its own folder and damages the copy.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest

from casecal.model import _native

pytestmark = pytest.mark.skipif(
    shutil.which("cc") is None and shutil.which("gcc") is None,
    reason="no C compiler: no kernel cache to damage",
)

PROBE = """
import sys, numpy as np, casecal as cc
from casecal.model import _evaluate  # no budget: auto compiles at the first batch (issue 23)
_evaluate.COMPILE_SECONDS_BASE = _evaluate.COMPILE_SECONDS_PER_INSTRUCTION = 0.0
r = cc.load_robot(ROBOT)
q = cc.poses.uniform(r, 400, seed=0)
out = [r.position(q).ravel()]
if ROBOT == "puma560":
    out.append(r.position_jacobian(q, ["theta*", "a*"])[0].ravel())
np.save(sys.argv[1], np.concatenate(out))
"""


def probe(cache, out, robot="rr", cwd=None):
    """Run the probe in a new process (a loaded library stays loaded in a process)."""
    env = {**os.environ, "CASECAL_CACHE": str(cache), "CASECAL_BACKEND": "auto"}
    code = PROBE.replace("ROBOT", repr(robot))
    done = subprocess.run(
        [sys.executable, "-c", code, str(out)], env=env, capture_output=True, text=True, cwd=cwd
    )
    return done.returncode, done.stderr, (np.load(out) if done.returncode == 0 else None)


@pytest.fixture(scope="module")
def good(tmp_path_factory):
    """A cache folder holding the rr kernel, and the kernel's values."""
    cache = tmp_path_factory.mktemp("cache")
    code, err, values = probe(cache, cache.parent / "good.npy")
    assert code == 0, err
    assert len(list(cache.glob("casecal_*.so"))) == 1, list(cache.iterdir())
    return cache, values


def resign(so):
    data = so.read_bytes()
    record = {"size": len(data), "sha256": hashlib.sha256(data).hexdigest()}
    so.with_suffix(".json").write_text(json.dumps(record))


def truncated(so):
    so.write_bytes(so.read_bytes()[:1000])


def garbage_resigned(so):
    so.write_bytes(np.random.default_rng(0).bytes(so.stat().st_size))
    resign(so)


def garbled_name_resigned(so):
    """A library naming a dependency in bytes that are not UTF-8: dlopen's message is not
    text (it raised UnicodeDecodeError)."""
    data = so.read_bytes()
    for name in (b"libm.so.6", b"sincos"):
        if name in data:
            so.write_bytes(data.replace(name, b"\xbd" * len(name), 1))
            resign(so)
            return
    pytest.skip("the kernel names neither libm nor sincos on this platform")


def sidecar(text):
    def write(so):
        so.with_suffix(".json").write_text(text)

    write.__name__ = f"sidecar {text}"
    return write


def no_sidecar(so):
    so.with_suffix(".json").unlink()


def no_library(so):
    so.unlink()


def folder_instead(so):
    so.unlink()
    so.mkdir()


def slow(how):
    """Damage casecal repaired before issue 20 (tests/test_kernel_cache.py): the slow run."""
    return pytest.param(how, marks=pytest.mark.slow, id=how.__name__)


DAMAGE = [
    slow(truncated),
    garbage_resigned,
    garbled_name_resigned,
    sidecar("[]"),
    sidecar("1"),
    sidecar("null"),
    sidecar('"x"'),
    slow(sidecar('{"x": 1}')),
    sidecar('{"size": "big", "sha256": []}'),
    slow(sidecar("{not json")),
    slow(no_sidecar),
    slow(no_library),
    folder_instead,
]


def damaged_copy(good, tmp_path, how):
    source, values = good
    cache = tmp_path / "cache"
    shutil.copytree(source, cache)
    (so,) = cache.glob("casecal_*.so")
    how(so)
    return cache, so, values


@pytest.mark.parametrize("how", DAMAGE, ids=lambda h: h.__name__)
def test_a_damaged_cache_evaluates_right_and_is_repaired(good, tmp_path, how, request):
    cache, so, values = damaged_copy(good, tmp_path, how)
    code, err, got = probe(cache, tmp_path / "out.npy")
    assert code == 0, err
    assert "Traceback" not in err and len(err.splitlines()) <= 1, err
    np.testing.assert_allclose(got, values, rtol=0, atol=1e-15)
    # repaired: a whole library with a record that verifies, which the next run loads as is
    assert so.is_file()
    record = json.loads(so.with_suffix(".json").read_text())
    assert record["size"] == so.stat().st_size
    before = so.stat().st_mtime_ns, so.stat().st_ino
    if "slow" in {m.name for m in request.node.iter_markers()}:
        code, err, got = probe(cache, tmp_path / "again.npy")
        assert code == 0 and err == "", err
        np.testing.assert_allclose(got, values, rtol=0, atol=1e-15)
    else:  # the same check in this process (a new one costs a second per case)
        digest = so.stem.removeprefix("casecal_")
        assert _native._load(so, digest) is not None
    assert (so.stat().st_mtime_ns, so.stat().st_ino) == before  # loaded, not rebuilt


def test_a_folder_with_files_in_the_kernels_place_is_left_alone(good, tmp_path):
    """Not ours to delete: evaluate without the kernel, say so once, touch nothing."""
    cache, so, values = damaged_copy(good, tmp_path, no_library)
    so.mkdir()
    (so / "notes.txt").write_text("mine")
    code, err, got = probe(cache, tmp_path / "out.npy")
    assert code == 0, err
    assert len(err.splitlines()) == 1 and so.name in err and "Traceback" not in err, err
    np.testing.assert_allclose(got, values, rtol=0, atol=1e-12)
    assert (so / "notes.txt").read_text() == "mine"


def unwritable_under_a_file(tmp_path):
    (tmp_path / "a-file").write_text("")
    return tmp_path / "a-file" / "cache"


def read_only_folder(tmp_path):
    if os.geteuid() == 0:
        pytest.skip("root writes into read-only folders")
    cache = tmp_path / "cache"
    cache.mkdir()
    cache.chmod(0o555)
    return cache


def failing_compiler(tmp_path, monkeypatch):
    """Each kernel's compile fails with a message naming its own file."""
    monkeypatch.setenv("CC", shutil.which("false") or pytest.skip("no 'false' command"))
    return tmp_path / "cache"


@pytest.mark.parametrize("where", [unwritable_under_a_file, read_only_folder, failing_compiler])
def test_an_unwritable_cache_warns_once_per_process(tmp_path, monkeypatch, where):
    cache = where(tmp_path, monkeypatch) if where is failing_compiler else where(tmp_path)
    try:
        code, err, got = probe(cache, tmp_path / "out.npy", robot="puma560")
    finally:
        if cache.exists():
            cache.chmod(0o755)
    assert code == 0, err
    # two kernels (positions, Jacobian) could not be built: one line for both
    assert len(err.splitlines()) == 1 and "numpy" in err, err
    env = {**os.environ, "CASECAL_BACKEND": "numpy"}
    code = PROBE.replace("ROBOT", "'puma560'")
    ref = tmp_path / "ref.npy"
    subprocess.run([sys.executable, "-c", code, str(ref)], env=env, check=True)
    np.testing.assert_allclose(got, np.load(ref), rtol=0, atol=1e-12)


@pytest.mark.parametrize("relative", [".", "kernels"])
def test_a_relative_cache_folder_is_used(good, tmp_path, relative):
    """``CASECAL_CACHE=.`` built the kernel, then dlopen searched the library path for it."""
    _, values = good
    code, err, got = probe(relative, tmp_path / "out.npy", cwd=tmp_path)
    assert code == 0 and err == "", err
    np.testing.assert_allclose(got, values, rtol=0, atol=1e-15)
    assert len(list((tmp_path / relative).glob("casecal_*.so"))) == 1
