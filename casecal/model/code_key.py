"""A key for a user function's code, stable across processes and changed by any edit.

Compiled kernels and the numpy evaluator's code are cached on disk under a key that holds
each error term's `fingerprint`: a function whose key stays the same after its behaviour
changed would be served the old numbers. So the key covers what the function computes
with: its code (and the code nested in it), its constants, defaults and closure values;
the module-level numbers, arrays, tuples and dicts of them it reads; the module-level
functions of the user's own code it calls (followed, by their own key), directly or
through a user module (``helpers.offset(q)``). All of it as the process holds it, not as
the files on disk say: a file edited after its import is not what runs. Library
code (the standard library, site-packages: numpy, CasADi) is keyed by the versions
elsewhere, not here.

Not covered: a class's methods called through an instance, and values built at run time
in an object that is not data (give the term a new `kind` after such a change).
"""

from __future__ import annotations

import functools
import hashlib
import numbers
import os
import sys
import sysconfig
import types

import numpy as np

_DEPTH = 40  # helper chains deeper than this are named, not followed

# where the standard library and installed packages live: their code is not the user's
_LIBRARY = tuple(
    sorted(
        {
            os.path.realpath(path) + os.sep
            for name, path in sysconfig.get_paths().items()
            if name in ("stdlib", "platstdlib", "purelib", "platlib")
        }
    )
)


def fingerprint(function) -> str:
    """A hash of what `function` computes with (see the module's doc).

    Parameters
    ----------
    function : callable
        A Python function, a `functools.partial` of one, or any other object (keyed by its
        repr).

    Returns
    -------
    str
        16 hex digits, the same in every process for the same code and data.
    """
    return _Walk().key(function, 0)


class _Walk:
    """One key's walk through the functions it reaches: each is keyed once (helpers that
    call each other would otherwise be walked once per path, exponentially many), and one
    met again while its key is being made (recursion) stands by its name."""

    def __init__(self):
        self.keys: dict[int, str] = {}
        self.held: list = []  # what `keys` is indexed by stays alive, so ids stay unique

    def key(self, function, depth: int) -> str:
        if id(function) in self.keys:
            return self.keys[id(function)]
        name = getattr(function, "__qualname__", type(function).__name__)
        if depth > _DEPTH:  # deeper than any helper chain a term is written with
            return name
        self.held.append(function)
        self.keys[id(function)] = name  # while in progress: a cycle back here sees the name
        if isinstance(function, functools.partial):
            parts = (function.func, function.args, function.keywords)
        elif hasattr(function, "__code__"):
            closure = [c.cell_contents for c in (function.__closure__ or ())]
            read = self._globals_read(function, depth)
            parts = (function.__code__, function.__defaults__, function.__kwdefaults__)
            parts += (closure, read)
        else:
            self.keys[id(function)] = repr(function)
            return repr(function)
        text = repr(self._stable(parts, depth + 1))
        self.keys[id(function)] = hashlib.sha256(text.encode()).hexdigest()[:16]
        return self.keys[id(function)]

    def _globals_read(self, function, depth: int) -> list:
        """``(name, key)`` of the module-level names `function`'s code reads that decide
        what it computes: data, the user's own functions, and those of the user's own
        modules."""
        module = getattr(function, "__globals__", {})
        names = sorted(_names(function.__code__))
        read = []
        for name in names:
            if name not in module:
                continue  # a builtin, an attribute's name, or not yet defined
            value = module[name]
            if isinstance(value, types.ModuleType) and _is_users(value):
                # ``helpers.offset(q)``: the names read are among the code's names too
                inner = vars(value)
                parts = [(n, self._keyed(inner[n], depth)) for n in names if n in inner]
                read.append((name, ("module", [(n, k) for n, k in parts if k is not None])))
            elif (key := self._keyed(value, depth)) is not None:
                read.append((name, key))
        return read

    def _keyed(self, value, depth: int):
        """The key of a module-level `value` a function reads, or None when it is not one
        that decides what the function computes (a library's function, a class, a
        module)."""
        if _is_data(value):
            return value
        if hasattr(value, "__code__") and _is_users(sys.modules.get(value.__module__)):
            return ("function", self.key(value, depth + 1))
        return None

    def _stable(self, value, depth: int):
        """`value` with code objects and functions replaced by what defines them, and
        arrays by a hash of their bytes (their repr elides the middle of a long one)."""
        if isinstance(value, np.ndarray):
            digest = hashlib.sha256(np.ascontiguousarray(value).tobytes()).hexdigest()
            return ("array", value.dtype.str, value.shape, digest)
        if isinstance(value, types.CodeType):
            return (value.co_code, self._stable(value.co_consts, depth), value.co_names)
        if isinstance(value, (tuple, list)):
            return tuple(self._stable(v, depth) for v in value)
        if isinstance(value, dict):
            return tuple((k, self._stable(v, depth)) for k, v in value.items())
        if isinstance(value, (set, frozenset)):  # ordered by the per-process hash seed
            return ("set", tuple(sorted(repr(self._stable(v, depth)) for v in value)))
        if hasattr(value, "__code__") or isinstance(value, functools.partial):
            return self.key(value, depth)
        return value


def _names(code: types.CodeType) -> set[str]:
    """The global names `code` and the code nested in it read."""
    names = set(code.co_names)
    for c in code.co_consts:
        if isinstance(c, types.CodeType):
            names |= _names(c)
    return names


def _is_data(value) -> bool:
    if isinstance(value, (numbers.Number, str, bytes, np.ndarray)):
        return True
    if isinstance(value, (tuple, list)):
        return all(_is_data(v) for v in value)
    if isinstance(value, dict):
        return all(_is_data(k) and _is_data(v) for k, v in value.items())
    return False


def _is_users(module) -> bool:
    """Whether `module` is the user's code: not built in, not the standard library, not an
    installed package. A module without a file (``python -c``, a notebook) is the user's,
    and so is one that cannot be found (code run by `exec`): followed rather than missed."""
    if module is None:
        return True
    file = getattr(module, "__file__", None)
    if file is None:
        return module.__name__ == "__main__"
    return not os.path.realpath(file).startswith(_LIBRARY)
