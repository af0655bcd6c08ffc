"""A key for a function's code and data, stable across processes and changed by an edit.

An error term's key (`casecal.model.terms`) names its graph in a process, and casecal's own
terms' kernels on disk. So it covers what the function computes with, as the process holds
it (a file edited after its import is not what runs):

- its code, and the code nested in it (argument names and flags included), its defaults
  and its closure values;
- the module-level values it reads: numbers, arrays, CasADi matrices, containers and
  objects of them (their attributes), tables of functions;
- the user's own functions, classes (their methods) and modules it reaches, by name, by
  attribute (``helpers.offset(q)``, ``pkg.geo.offset(q)``), or by an import inside it;
  bound methods with their instance, callable objects with their class, partials and
  decorated functions with what they wrap;
- library code (the standard library, installed packages) by the package's version, and
  casecal's own model by its source (`casecal.model._native.fingerprint`).

What the walk cannot key (an object that shows only its memory address, data nested past
Python's recursion limit, helpers nested deeper than `_DEPTH`, an object that raises when
read) is named in `CodeKey.unseen`. A Python function's behaviour cannot be keyed
completely from outside (a value read from a file, a method patched at run time): a
user's term is therefore keyed on disk by the graph it builds, never by this key alone.
"""

from __future__ import annotations

import dis
import functools
import hashlib
import importlib.metadata
import importlib.util
import numbers
import os
import sys
import sysconfig
import types
from dataclasses import dataclass

import casadi as ca
import numpy as np

_DEPTH = 40  # helper chains deeper than this are not followed (and the key says so)

# where the standard library and installed packages live: their code is not the user's
_PATHS = sysconfig.get_paths()
_LIBRARY = tuple(
    sorted(
        {
            os.path.realpath(_PATHS[name]) + os.sep
            for name in ("stdlib", "platstdlib", "purelib", "platlib")
            if name in _PATHS
        }
    )
)


@dataclass(frozen=True)
class CodeKey:
    """The key of a function (`code_key`).

    Attributes
    ----------
    digest : str
        16 hex digits, the same in every process for the same code and data.
    unseen : tuple of str
        What the function reads that the digest does not cover, in words; empty when it
        covers everything.
    """

    digest: str
    unseen: tuple[str, ...] = ()


def code_key(function) -> CodeKey:
    """The key of what `function` computes with (see the module's doc).

    Parameters
    ----------
    function : callable
        A function, lambda, bound method, `functools.partial`, decorated function or
        callable object.
    """
    walk = _Walk()
    try:
        text = walk.function(function, 0)
    except RecursionError:
        problem = "data nested too deep"
    except Exception as exc:  # the user's objects: whatever their attributes raise
        problem = f"an object that raises when read ({type(exc).__name__})"
    else:
        return CodeKey(text, tuple(dict.fromkeys(walk.unseen)))
    name = str(getattr(function, "__qualname__", type(function).__name__))
    return CodeKey(hashlib.sha256(name.encode()).hexdigest()[:16], (problem,))


def fingerprint(function) -> str:
    """`code_key(function).digest`."""
    return code_key(function).digest


class _Walk:
    """One key's walk through what a function reaches: each function is keyed once
    (helpers that call each other would otherwise be walked once per path), and one met
    again while its key is being made (recursion) stands by its name."""

    def __init__(self):
        self.keys: dict[int, str] = {}
        self.held: list = []  # what `keys` is indexed by stays alive, so ids stay unique
        self.unseen: list[str] = []
        self.open: set[int] = set()  # containers being keyed: a cycle back is marked
        self.modules: set[tuple] = set()  # (module, names read) followed

    def function(self, f, depth: int) -> str:
        """The key (16 hex digits) of callable `f`."""
        if id(f) in self.keys:
            return self.keys[id(f)]
        name = getattr(f, "__qualname__", type(f).__name__)
        if depth > _DEPTH:
            self.unseen.append(f"helpers nested more than {_DEPTH} deep ({name})")
            return name
        self.held.append(f)
        self.keys[id(f)] = name  # while in progress: a cycle back here sees the name
        text = repr(self._parts(f, depth))
        self.keys[id(f)] = hashlib.sha256(text.encode()).hexdigest()[:16]
        return self.keys[id(f)]

    def _parts(self, f, depth: int):
        if isinstance(f, functools.partial):
            parts = (f.func, f.args, f.keywords)
            return ("partial", *(self.value(x, depth) for x in parts))
        if isinstance(f, types.MethodType):
            return ("method", self.value(f.__func__, depth), self.value(f.__self__, depth))
        if isinstance(f, types.FunctionType):
            cells = []
            for cell in f.__closure__ or ():
                try:
                    cells.append(self.value(cell.cell_contents, depth))
                except ValueError:  # a cell not yet assigned
                    cells.append("<empty cell>")
            code = self.value(f.__code__, depth)
            defaults = self.value((f.__defaults__, f.__kwdefaults__), depth)
            return ("function", code, defaults, cells, self._globals_read(f, depth))
        if hasattr(f, "__wrapped__"):  # functools.lru_cache, functools.wraps
            return ("wrapped", self.function(f.__wrapped__, depth + 1))
        if isinstance(f, (types.BuiltinFunctionType, np.ufunc, type)):
            return self.value(f, depth)
        return ("object", self.value(f, depth))  # a callable instance: class and state

    def _globals_read(self, f, depth: int) -> list:
        """``(name, key)`` of the module-level names `f`'s code reads, and of the user
        modules it imports inside itself."""
        module = f.__globals__
        names = _names(f.__code__)
        read = [(n, self.reached(module[n], names, depth)) for n in sorted(names) if n in module]
        for name in _imports(f.__code__, module.get("__package__")):
            try:  # at once, as the function would when it runs: what is loaded is what runs
                imported = importlib.import_module(name)
            except Exception as exc:  # the user's module: whatever it raises
                self.unseen.append(f"a module it imports ({name}) that fails: {exc!r}")
                continue
            read.append((f"import {name}", self.reached(imported, names, depth)))
        return read

    def reached(self, value, names: set[str], depth: int):
        """The key of a module-level `value` reached by name (`names`: the attribute
        names the reaching code reads, which select a user module's members)."""
        if isinstance(value, types.ModuleType):
            if not _is_users(value):
                return ("library", *_version(value.__name__))
            seen = (value.__name__, frozenset(names))
            if seen in self.modules:
                return ("module", value.__name__)
            self.modules.add(seen)
            inner = vars(value)
            members = [
                (n, self.reached(inner[n], names, depth)) for n in sorted(names & inner.keys())
            ]
            return ("module", value.__name__, members)
        return self.value(value, depth)

    def value(self, v, depth: int):
        """`v` as text-stable data: functions by their key, arrays by a hash of their bytes
        (their repr elides the middle of a long one), objects by their class and state."""
        if isinstance(v, np.generic):
            return ("numpy", v.dtype.str, v.item())
        if v is None or isinstance(v, (bool, str, bytes, numbers.Number)):
            return v
        if isinstance(v, np.ndarray):
            if v.dtype.hasobject:
                return ("array", v.shape, self.value(v.ravel().tolist(), depth))
            digest = hashlib.sha256(np.ascontiguousarray(v).tobytes()).hexdigest()
            return ("array", v.dtype.str, v.shape, digest)
        if isinstance(v, ca.DM):
            return ("DM", self.value(np.array(v), depth))
        if isinstance(v, (ca.SX, ca.MX)):  # str() of a deep expression overflows the stack
            graph = ca.Function("v", ca.symvar(v), [v]).serialize()
            return (type(v).__name__, v.shape, hashlib.sha256(graph.encode()).hexdigest())
        if isinstance(v, types.CodeType):
            counts = (v.co_argcount, v.co_posonlyargcount, v.co_kwonlyargcount, v.co_flags)
            names = (v.co_names, v.co_varnames, v.co_freevars, v.co_cellvars)
            return (v.co_code, self.value(v.co_consts, depth), names, counts)
        if isinstance(v, types.ModuleType):
            return ("module", v.__name__) if _is_users(v) else ("library", *_version(v.__name__))
        if isinstance(v, (tuple, list, dict, set, frozenset)):
            return self._container(v, depth)
        if isinstance(v, type):
            return self._class(v, depth)
        if isinstance(v, (types.MethodType, functools.partial)) or (
            _is_function_like(v) and _is_users(_module_of(v))
        ):
            return ("function", self.function(v, depth + 1))
        name = getattr(v, "__qualname__", None) or getattr(v, "__name__", None)
        if (_is_function_like(v) or isinstance(v, np.ufunc)) and isinstance(name, str):
            return ("library", *_version(_module_name(v)), name)
        return self._object(v, depth)

    def _container(self, v, depth: int):
        if id(v) in self.open:
            return ("cycle",)
        self.open.add(id(v))
        try:
            if isinstance(v, dict):
                items = [(self.value(k, depth), self.value(x, depth)) for k, x in v.items()]
                return ("dict", sorted(items, key=repr))  # a set's order is per process
            if isinstance(v, (set, frozenset)):
                return ("set", sorted((self.value(x, depth) for x in v), key=repr))
            return (type(v).__name__, [self.value(x, depth) for x in v])
        finally:
            self.open.discard(id(v))

    def _class(self, cls: type, depth: int):
        if not _is_users(_module_of(cls)):
            return ("library", *_version(cls.__module__), cls.__qualname__)
        if id(cls) in self.open:
            return ("class", cls.__qualname__)
        self.open.add(id(cls))
        try:
            members = []
            for n, m in sorted(vars(cls).items()):
                if n.startswith("__") and n not in ("__call__", "__init__", "__post_init__"):
                    continue  # the class's machinery (__dict__, __module__, __doc__, ...)
                if isinstance(m, (staticmethod, classmethod)):
                    m = m.__func__
                if isinstance(m, property):
                    m = (m.fget, m.fset)
                if _is_plain(m) or _is_function_like(m):  # not the machinery (_abc_impl)
                    members.append((n, self.value(m, depth)))
            bases = [self._class(b, depth) for b in cls.__bases__ if b is not object]
            return ("class", cls.__qualname__, bases, members)
        finally:
            self.open.discard(id(cls))

    def _object(self, v, depth: int):
        """An instance: its class and its state (attributes or slots)."""
        state = getattr(v, "__dict__", None)
        slots = [s for c in type(v).__mro__ for s in getattr(c, "__slots__", ())]
        if state is None and slots:
            state = {s: getattr(v, s, None) for s in slots}
        text = repr(v)
        if state is None:
            if " at 0x" in text:
                self.unseen.append(f"a {type(v).__name__} it shows only by its address")
                return ("opaque", type(v).__qualname__)
            return ("object", self._class(type(v), depth), text)
        if id(v) in self.open:
            return ("cycle",)
        self.open.add(id(v))
        try:
            return ("object", self._class(type(v), depth), self.value(dict(state), depth))
        finally:
            self.open.discard(id(v))


def _names(code: types.CodeType) -> set[str]:
    """The global and attribute names `code` and the code nested in it read."""
    names = set(code.co_names)
    for c in code.co_consts:
        if isinstance(c, types.CodeType):
            names |= _names(c)
    return names


@functools.lru_cache(maxsize=4096)  # code is immutable, and disassembling it is slow
def _imports(code: types.CodeType, package: str | None) -> tuple[str, ...]:
    """The full names of the modules `code` (and the code nested in it) imports when it
    runs: ``import helpers``, ``import pkg.geo``, ``from .elastic import moment``."""
    found = []
    constants: list = []
    for op in dis.get_instructions(code):
        if op.opname == "IMPORT_NAME":
            level = constants[-2] if len(constants) >= 2 and isinstance(constants[-2], int) else 0
            try:
                found.append(importlib.util.resolve_name("." * level + op.argval, package))
            except (ImportError, ValueError):
                continue  # a relative import outside a package fails when run, too
        constants = [*constants[-1:], op.argval] if op.opname == "LOAD_CONST" else []
    for c in code.co_consts:
        if isinstance(c, types.CodeType):
            found += _imports(c, package)
    return tuple(sorted(set(found)))


def _is_plain(v) -> bool:
    return v is None or isinstance(
        v, (bool, str, bytes, numbers.Number, np.ndarray, ca.DM, tuple, list, dict, set, frozenset)
    )


def _is_function_like(v) -> bool:
    return isinstance(
        v, (types.FunctionType, types.MethodType, functools.partial, types.BuiltinFunctionType)
    ) or hasattr(v, "__wrapped__")


def _module_name(v) -> str:
    return getattr(v, "__module__", None) or type(v).__module__ or ""


def _module_of(v):
    return sys.modules.get(_module_name(v))


def _is_users(module) -> bool:
    """Whether `module` is the user's code: not built in, not the standard library, not an
    installed package. A module without a file (``python -c``, a notebook) is the user's,
    and so is one that cannot be found (code run by `exec`): followed rather than missed."""
    if module is None:
        return True
    if module.__name__.startswith("casecal.model."):
        return False  # keyed by its source (`casecal.model._native.fingerprint`)
    file = getattr(module, "__file__", None)
    if file is None:
        return module.__name__ not in sys.builtin_module_names and module.__name__ != "builtins"
    return not os.path.realpath(file).startswith(_LIBRARY)


@functools.cache
def _version(module_name: str) -> tuple[str, str]:
    """``(package, version)`` of the installed package that holds `module_name`: its code
    is keyed by the version (an upgrade changes the key)."""
    top = module_name.split(".")[0]
    if top in sys.stdlib_module_names or top == "builtins":
        return top, sys.version
    found = getattr(sys.modules.get(top), "__version__", None)
    if isinstance(found, str):
        return top, found
    for distribution in _distributions().get(top, [top]):
        try:
            return top, importlib.metadata.version(distribution)
        except importlib.metadata.PackageNotFoundError:
            continue
    return top, "unknown version"


@functools.lru_cache(maxsize=1)
def _distributions() -> dict:
    return importlib.metadata.packages_distributions()
