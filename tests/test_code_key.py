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


# A user's term and an edit between two runs that share the disk cache. The last three are
# out of any reading of the code's reach (a module held in a closure, a class's operator, a
# file read when the graph is built): a user's kernels are keyed by the graph they build.
BETWEEN_RUNS = {
    "helper through its module": (
        {
            "user_helpers.py": "def offset(x):\n    return 0.5 * x\n",
            "user_terms.py": "import user_helpers\ndef build(ctx, term):\n"
            "    return ctx.p('k') * user_helpers.offset(ctx.q[2])\n",
        },
        ("user_helpers.py", "0.5->2.0"),
    ),
    "module held in a closure": (
        {
            "user_helpers.py": "def offset(x):\n    return 0.5 * x\n",
            "user_terms.py": "import user_helpers\ndef make(mod):\n"
            "    def build(ctx, term):\n        return ctx.p('k') * mod.offset(ctx.q[2])\n"
            "    return build\nbuild = make(user_helpers)\n",
        },
        ("user_helpers.py", "0.5->2.0"),
    ),
    "operator of a user class": (
        {
            "user_helpers.py": "class Gain:\n    def __mul__(self, x):\n        return 0.5 * x\n",
            "user_terms.py": "from user_helpers import Gain\nG = Gain()\n"
            "def build(ctx, term):\n    return ctx.p('k') * (G * ctx.q[2])\n",
        },
        ("user_helpers.py", "0.5->2.0"),
    ),
    "a file read when the graph is built": (
        {
            "gain.txt": "0.5\n",
            "user_terms.py": "import os, numpy as np\ndef build(ctx, term):\n"
            "    k = float(np.loadtxt(os.path.join(os.path.dirname(__file__), 'gain.txt')))\n"
            "    return ctx.p('k') * k * ctx.q[2]\n",
        },
        ("gain.txt", "0.5->2.0"),
    ),
}


@pytest.mark.parametrize("case", list(BETWEEN_RUNS))
def test_an_edit_between_two_runs_is_not_served_from_the_cache(tmp_path, case):
    """The user's path: run, edit, run again with the same cache (numpy's cached code;
    the C kernels share the key)."""
    files, (name, change) = BETWEEN_RUNS[case]
    code = tmp_path / "code"
    code.mkdir()
    for file, text in files.items():
        (code / file).write_text(text)
    env = {**os.environ, "CASECAL_CACHE": str(tmp_path / "cache"), "CASECAL_BACKEND": "numpy"}
    env["PYTHONDONTWRITEBYTECODE"] = "1"  # a .pyc of the same second and size would be stale

    def run(out):
        done = subprocess.run(
            [sys.executable, "-c", PROBE, str(tmp_path / out), str(code)],
            env=env,
            capture_output=True,
            text=True,
        )
        assert done.returncode == 0, done.stderr
        return np.load(tmp_path / out)

    half = run("half.npy")
    assert np.array_equal(half, run("again.npy"))
    entries = sorted((tmp_path / "cache").glob("casecal_*.numpy"))
    assert entries  # cached, so it could be stale
    old, new = change.split("->")
    (code / name).write_text(files[name].replace(old, new))
    doubled = run("doubled.npy")
    env["CASECAL_CACHE"] = str(tmp_path / "fresh")
    assert np.array_equal(doubled, run("fresh.npy"))
    assert np.abs(doubled - half).max() > 1e-4  # 0.01·1.5·q3 rad moves the tool by mm
    assert len(list((tmp_path / "cache").glob("casecal_*.numpy"))) > len(entries)


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
    real = code_key._Walk.function
    monkeypatch.setattr(
        code_key._Walk, "function", lambda self, f, d: calls.append(f) or real(self, f, d)
    )
    first = fingerprint(space["h0"])
    assert len(calls) == 1 + 12 * 12  # the first call, then each reads its twelve names
    assert fingerprint(space["h0"]) == first
    space["h7"].__code__ = (lambda x: x).__code__
    assert fingerprint(space["h0"]) != first  # a change deep in the cycle is seen


# A user's code before and after an edit that changes what its term computes: files of
# the user's modules, the term's function being `user_terms.BUILD`. Each edit must change
# the key (the review of the first version found each of these served old numbers).
EDITS = {
    "bound method's instance": (
        {
            "user_terms.py": "class T:\n    def __init__(self, s):\n        self.s = s\n"
            "    def build(self, ctx, term):\n        return self.s * ctx.q[2]\n"
            "BUILD = T(0.5).build\n"
        },
        {"user_terms.py": "T(0.5)->T(2.0)"},
    ),
    "callable object's method": (
        {
            "user_terms.py": "import dataclasses\n@dataclasses.dataclass\nclass T:\n"
            "    s: float = 0.5\n    def __call__(self, ctx, term):\n"
            "        return self.s * ctx.q[2]\nBUILD = T()\n"
        },
        {"user_terms.py": "self.s * ->2 * self.s * "},
    ),
    "module imported inside the function": (
        {
            "user_terms.py": "def BUILD(ctx, term):\n    import user_helpers\n"
            "    return user_helpers.offset(ctx.q[2])\n",
            "user_helpers.py": "def offset(x):\n    return 0.5 * x\n",
        },
        {"user_helpers.py": "0.5->2.0"},
    ),
    "submodule of a user package": (
        {
            "user_terms.py": "import upkg.geo\ndef BUILD(ctx, term):\n"
            "    return upkg.geo.offset(ctx.q[2])\n",
            "upkg/__init__.py": "",
            "upkg/geo.py": "def offset(x):\n    return 0.5 * x\n",
        },
        {"upkg/geo.py": "0.5->2.0"},
    ),
    "CasADi matrix": (
        {
            "user_terms.py": "import casadi as ca\nG = ca.DM([0.5, 1.0])\n"
            "def BUILD(ctx, term):\n    return G[1] * ctx.q[2]\n"
        },
        {"user_terms.py": "1.0]->2.0]"},
    ),
    "a config object and a dict holding None": (
        {
            "user_terms.py": "import types\nCFG = types.SimpleNamespace(s=0.5)\n"
            "OPT = {'s': 0.5, 'axis': None}\n"
            "def BUILD(ctx, term):\n    return CFG.s * OPT['s'] * ctx.q[2]\n"
        },
        {"user_terms.py": "(s=0.5)->(s=2.0)"},
    ),
    "partial and cached helpers": (
        {
            "user_terms.py": "import functools\ndef _scale(k, x):\n    return k * x\n"
            "offset = functools.partial(_scale, 0.5)\n"
            "@functools.lru_cache\ndef gain(i):\n    return 1.0 + i\n"
            "def BUILD(ctx, term):\n    return gain(1) * offset(ctx.q[2])\n"
        },
        {"user_terms.py": "_scale, 0.5)->_scale, 2.0)"},
    ),
    "cached helper's body": (
        {
            "user_terms.py": "import functools\n"
            "@functools.lru_cache\ndef gain(i):\n    return 1.0 + i\n"
            "def BUILD(ctx, term):\n    return gain(1) * ctx.q[2]\n"
        },
        {"user_terms.py": "1.0 + i->3.0 + i"},
    ),
    "table of functions and a static method": (
        {
            "user_terms.py": "def a(x):\n    return 0.5 * x\nOPS = {'a': a}\n"
            "class H:\n    @staticmethod\n    def offset(x):\n        return 3.0 * x\n"
            "def BUILD(ctx, term):\n    return OPS['a'](ctx.q[2]) + H.offset(ctx.q[1])\n"
        },
        {"user_terms.py": "0.5 * x->0.7 * x"},
    ),
    "static method's body": (
        {
            "user_terms.py": "class H:\n    @staticmethod\n    def offset(x):\n"
            "        return 3.0 * x\n"
            "def BUILD(ctx, term):\n    return H.offset(ctx.q[1])\n"
        },
        {"user_terms.py": "3.0 * x->4.0 * x"},
    ),
    "middle of a long array in a closed-over object": (
        {
            "user_terms.py": "import dataclasses, numpy as np\n@dataclasses.dataclass\n"
            "class Cal:\n    table: object\ndef make(cal):\n"
            "    def build(ctx, term):\n        return float(cal.table[2500]) * ctx.q[2]\n"
            "    return build\nT = np.ones(5000)\nT[2500] = 0.5\nBUILD = make(Cal(T))\n"
        },
        {"user_terms.py": "T[2500] = 0.5->T[2500] = 2.0"},
    ),
    "argument names swapped": (
        {
            "user_terms.py": "def f(a, b):\n    return a - 2 * b\n"
            "def BUILD(ctx, term):\n    return f(a=ctx.q[1], b=ctx.q[2])\n"
        },
        {"user_terms.py": "def f(a, b):\n    return a - 2 * b->def f(b, a):\n    return b - 2 * a"},
    ),
}


def _key_of_build(folder, files):
    """The key of `user_terms.BUILD` imported from `files` written into `folder`."""
    from casecal.model.code_key import code_key

    for name, text in files.items():
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        (folder / name).write_text(text)
    mine = ("user_terms", "user_helpers", "upkg", "upkg.geo")
    for name in mine:
        sys.modules.pop(name, None)
    sys.path.insert(0, str(folder))
    importlib.invalidate_caches()
    try:
        return code_key(importlib.import_module("user_terms").BUILD)
    finally:
        sys.path.remove(str(folder))
        for name in mine:
            sys.modules.pop(name, None)


@pytest.mark.parametrize("case", list(EDITS))
def test_an_edit_changes_the_key(tmp_path, case):
    files, edits = EDITS[case]
    edited = dict(files)
    for name, change in edits.items():
        old, new = change.split("->")
        assert old in files[name]
        edited[name] = files[name].replace(old, new)
    before = _key_of_build(tmp_path / "a", files)
    again = _key_of_build(tmp_path / "b", files)
    after = _key_of_build(tmp_path / "c", edited)
    assert before.unseen == after.unseen == ()  # all of it keyed, none left to chance
    assert before.digest == again.digest  # the same code in another folder: the same key
    assert after.digest != before.digest


def test_casecals_own_terms_are_keyed_whole():
    """Gravity compliance (masses known, lumped, lateral on a tree) and harmonics: keyed by
    their code, none by its graph (which every process would have to build first)."""
    import dataclasses

    import casecal as cc
    from casecal.report import studies_compliance, studies_elastic

    rigid = cc.load_robot("kr15_2")
    heavy = dataclasses.replace(rigid, inertials=studies_compliance.INERTIALS, auto_beta=False)
    robots = [heavy.with_compliance([2, 3]), rigid.with_compliance([2, 3])]
    robots += list(studies_elastic.models().values())
    robots += [rigid.with_joint_harmonics(2, 2)]
    terms = [t for r in robots for t in r.terms]
    assert len({t.kind for t in terms}) >= 4
    assert not any(t.by_graph for t in terms), [t.code for t in terms if t.by_graph]


def test_odd_functions_are_keyed_without_a_traceback():
    """An empty closure cell, data that holds itself, data nested past the recursion
    limit, builtins and ufuncs: a key, and what it misses said."""
    from casecal.model.code_key import code_key

    def later():
        return cell  # assigned after: the cell is empty now

    looped = [1.0]
    looped.append(looped)
    deep = [0.0]
    for _ in range(5000):
        deep = [deep]

    assert code_key(later).unseen == ()
    assert code_key(lambda ctx, t: looped[0] * ctx.q[0]).unseen == ()
    assert code_key(lambda ctx, t: deep[0] * ctx.q[0]).unseen == ("data nested too deep",)
    for f in (abs, np.sin, np.vectorize(abs)):
        assert code_key(f).digest
    cell = 1.0


GRAPH_KEYED = textwrap.dedent(
    """
    import sys, threading, numpy as np, casecal as cc
    from casecal.model import _native
    from casecal.model.terms import ErrorTerm
    GUARD = threading.Lock()  # shows only its memory address: its state cannot be keyed
    def build(ctx, term):
        with GUARD:
            return ctx.p("k") * ctx.q[2]
    term = ErrorTerm("guarded", 2, ("k",), build)
    assert term.by_graph, term.code
    if sys.argv[2] == "warm":  # the kernels must come from the cache
        def refuse(*args, **kwargs):
            raise AssertionError("compiled again")
        _native._build = refuse
    r = cc.load_robot("puma560").with_terms(term).with_parameters({"k": 0.01})
    q = cc.poses.uniform(r, 300, seed=0)
    J, _ = r.position_jacobian(q, ["theta*", "k"])
    np.save(sys.argv[1], np.concatenate([r.position(q).ravel(), J.ravel()]))
    """
)


def test_a_users_term_compiles_once_per_machine(tmp_path):
    """Keyed by its graph, whatever its code reads: a second process loads the kernels
    the first compiled, and both give CasADi's own numbers."""
    env = {**os.environ, "CASECAL_CACHE": str(tmp_path / "cache")}

    def run(name, backend, warm="cold"):
        done = subprocess.run(
            [sys.executable, "-c", GRAPH_KEYED, str(tmp_path / name), warm],
            env={**env, "CASECAL_BACKEND": backend},
            capture_output=True,
            text=True,
        )
        assert done.returncode == 0, done.stderr
        return np.load(tmp_path / name)

    cold = run("cold.npy", "c")
    assert list((tmp_path / "cache").glob("casecal_*.so"))
    warm = run("warm.npy", "c", "warm")
    reference = run("casadi.npy", "casadi")
    assert np.array_equal(cold, warm)
    assert np.allclose(cold, reference, rtol=0, atol=1e-12)


KEYS = textwrap.dedent(
    """
    import types, casecal as cc
    from casecal.model.code_key import code_key
    class Gain:
        def __init__(self, s):
            self.s = s
        def build(self, ctx, term):
            return self.s * ctx.q[2]
    config = types.SimpleNamespace(s=0.5, names={"a", "b", "c", "d"})
    table = {k: len(k) for k in {"alpha", "beta", "gamma", "delta"}}
    def closed(ctx, term):
        return config.s * table["beta"] * ctx.q[2]
    print([code_key(f) for f in (Gain(0.5).build, closed)])
    """
)


def _under_seeds(script: str, seeds) -> list[str]:
    """What `script` prints in a new process per hash seed."""
    return [
        subprocess.run(
            [sys.executable, "-c", script],
            capture_output=True,
            text=True,
            check=True,
            env={**os.environ, "PYTHONHASHSEED": seed},
        ).stdout
        for seed in seeds
    ]


def test_objects_sets_and_methods_key_the_same_in_every_process():
    """No memory address and no hash order in a key, or every process compiles again."""
    runs = _under_seeds(KEYS, ("1", "2", "3"))
    assert "unseen=()" in runs[0] and runs[0] == runs[1] == runs[2]


_FINGERPRINTS = """
import functools
from casecal.model import terms

def user(ctx, term, scale=2.0):
    weights = [scale * i for i in range(3)]  # a comprehension: nested code
    k = ctx.p("k") if "k" in {"k", "j"} else 0  # a set literal: a frozenset constant
    return sum(w * ctx.q[i] for i, w in enumerate(weights)) * k

own = {n: f for n, f in vars(terms).items() if n.startswith("_") and hasattr(f, "__code__")}
both = {name: terms.fingerprint(f) for name, f in own.items()}
both["user"] = terms.fingerprint(user)
both["partial"] = terms.fingerprint(functools.partial(user, scale=3.0))
print(sorted(both.items()))
"""


def test_a_term_keys_its_kernels_the_same_in_every_process():
    """The kernels of a term are compiled once per machine: the key of its function
    must not hold a memory address (a comprehension's code, a function in its closure)
    or a set's hash order, or every process (each study worker) compiles them again."""
    runs = _under_seeds(_FINGERPRINTS, ("1", "2"))
    assert "'_lumped'" in runs[0] and "'user'" in runs[0]
    assert runs[0] == runs[1]
