"""The key of a user term's code (`casecal.model.code_key.fingerprint`).

Kernels and numpy evaluators are cached on disk under it: an edit that changes what a
term computes must change its key, or a later process is served the old numbers. The
helpers a term calls, in its own module or through another of the user's modules, count.
"""

from __future__ import annotations

import importlib
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from casecal.model.code_key import fingerprint

HELPERS = """
SCALE = 0.5

def offset(x):
    return SCALE * x
"""

TERMS = """
import helpers_{tag}
from helpers_{tag} import offset as direct

GAINS = {{"first": 1.0, "second": 2.0}}

def _local(x):
    return 3.0 * x

def build(ctx, term):
    q = ctx.q
    return ctx.p("k") * (direct(q[0]) + helpers_{tag}.offset(q[1]) * GAINS["second"] + _local(q[2]))
"""


@pytest.fixture
def user_modules(tmp_path, request):
    """A user's terms module and the helpers module it calls, imported fresh."""
    tag = request.node.name.replace("[", "_").replace("]", "").replace("-", "_")
    (tmp_path / f"helpers_{tag}.py").write_text(HELPERS)
    (tmp_path / f"terms_{tag}.py").write_text(TERMS.format(tag=tag))
    sys.path.insert(0, str(tmp_path))
    try:
        terms = importlib.import_module(f"terms_{tag}")
        yield terms, sys.modules[f"helpers_{tag}"]
    finally:
        sys.path.remove(str(tmp_path))
        sys.modules.pop(f"terms_{tag}", None)
        sys.modules.pop(f"helpers_{tag}", None)


def test_an_edited_helper_in_the_terms_module_changes_the_key(user_modules):
    terms, _ = user_modules
    before = fingerprint(terms.build)
    terms._local.__code__ = (lambda x: 4.0 * x).__code__
    assert fingerprint(terms.build) != before


def test_an_edited_helper_in_another_user_module_changes_the_key(user_modules):
    """Reached both ways: imported by name, and through the module's attribute."""
    terms, helpers = user_modules
    before = fingerprint(terms.build)
    helpers.offset.__code__ = (lambda x: SCALE * x * x).__code__  # noqa: F821
    assert fingerprint(terms.build) != before


def test_a_helper_reached_only_through_its_module_is_followed(user_modules):
    terms, helpers = user_modules
    before = fingerprint(terms.build)
    terms.direct = lambda x: x  # the name-imported path no longer reaches offset
    once = fingerprint(terms.build)
    assert once != before
    helpers.offset.__code__ = (lambda x: 2 * x).__code__
    assert fingerprint(terms.build) != once


def test_a_helpers_constant_and_a_table_of_gains_change_the_key(user_modules):
    terms, helpers = user_modules
    before = fingerprint(terms.build)
    helpers.SCALE = 0.25
    scaled = fingerprint(terms.build)
    assert scaled != before
    terms.GAINS["second"] = 2.5
    assert fingerprint(terms.build) != scaled
    terms.GAINS["second"], helpers.SCALE = 2.0, 0.5
    assert fingerprint(terms.build) == before  # data, not identity: nothing else moved


def test_library_code_is_not_followed():
    """numpy's own functions are keyed by its version elsewhere: following them would
    cost every key a walk through the library."""
    from casecal.model import code_key

    assert not code_key._is_users(np)
    assert not code_key._is_users(os)
    assert code_key._is_users(sys.modules[__name__])


PROBE = textwrap.dedent(
    """
    import sys, numpy as np, casecal as cc
    sys.path.insert(0, sys.argv[2])
    from casecal.model import _evaluate
    from casecal.model.terms import ErrorTerm
    import user_terms
    _evaluate.COMPILE_MAX_INSTRUCTIONS = 0  # numpy, as for a Function too long for GCC
    r = cc.load_robot("puma560").with_terms([ErrorTerm("mine", 2, ("k",), user_terms.build)])
    r = r.with_parameters({"k": 0.01})
    q = cc.poses.uniform(r, 300, seed=0)
    np.save(sys.argv[1], r.position(q))
    """
)


def test_a_helper_edited_between_two_processes_is_not_served_from_the_cache(tmp_path):
    """The user's path: run, edit the helper file, run again with the same cache."""
    code = tmp_path / "code"
    code.mkdir()
    (code / "user_helpers.py").write_text("def offset(x):\n    return 0.5 * x\n")
    (code / "user_terms.py").write_text(
        "import user_helpers\n\ndef build(ctx, term):\n"
        "    return ctx.p('k') * user_helpers.offset(ctx.q[2])\n"
    )
    env = {**os.environ, "CASECAL_CACHE": str(tmp_path / "cache"), "CASECAL_BACKEND": "numpy"}
    env["PYTHONDONTWRITEBYTECODE"] = "1"  # a .pyc of the same second and size would be stale

    def run(name):
        out = tmp_path / f"{name}.npy"
        done = subprocess.run(
            [sys.executable, "-c", PROBE, str(out), str(code)],
            env=env,
            capture_output=True,
            text=True,
        )
        assert done.returncode == 0, done.stderr
        return np.load(out)

    half = run("half")
    assert list((tmp_path / "cache").glob("casecal_*.numpy"))  # cached, so it could be stale
    (code / "user_helpers.py").write_text("def offset(x):\n    return 2.0 * x\n")
    doubled = run("doubled")
    env["CASECAL_CACHE"] = str(tmp_path / "fresh")
    assert np.array_equal(doubled, run("fresh"))
    assert np.abs(doubled - half).max() > 1e-4  # 0.01·1.5·q3 rad moves the tool by mm


def test_with_terms_takes_a_list_and_refuses_what_is_not_a_term():
    import casecal as cc
    from casecal.model.terms import ErrorTerm

    term = ErrorTerm("mine", 2, ("k",), lambda ctx, t: ctx.p("k") * ctx.q[2])
    robot = cc.load_robot("puma560")
    assert robot.with_terms([term]).terms == robot.with_terms(term).terms == (term,)
    with pytest.raises(cc.CalibrationError, match="ErrorTerm objects, not str"):
        robot.with_terms("mine")


def test_helpers_that_call_each_other_are_keyed_once_each(monkeypatch):
    """Twelve helpers that all call each other: each is keyed once per key, not once per
    path through them (11^8 paths had been walked), and recursion ends."""
    from casecal.model import code_key

    names = [f"h{i}" for i in range(12)]
    source = "".join(
        f"def {n}(x):\n    return x if x < 1 else "
        + " + ".join(f"{m}(x - 1)" for m in names)
        + "\n"
        for n in names
    )
    space = {"__name__": "not_imported"}  # code run by exec: followed
    exec(source, space)
    calls = []
    real = code_key._Walk.key
    monkeypatch.setattr(
        code_key._Walk, "key", lambda self, f, d: calls.append(f) or real(self, f, d)
    )
    first = fingerprint(space["h0"])
    assert len(calls) == 1 + 12 * 12  # the first call, then each reads its twelve names
    assert fingerprint(space["h0"]) == first
    space["h7"].__code__ = (lambda x: x).__code__
    assert fingerprint(space["h0"]) != first  # a change deep in the cycle is seen
