"""Batched evaluation of a chain's outputs: compiled C where a compiler is present, else
numpy over the CasADi instruction list (`casecal.model._vectorised`), else CasADi's own.

`casecal.model.kinematics.Chain.evaluate` makes one `Evaluator` per output kind and
parameter columns and calls it on all poses at once.

When to compile (backend "auto", issue 23): a kernel in the disk cache is used at once. One
that is not is compiled only once it pays, by a ski-rental rule: until then numpy answers
(the same bits, about four times C's time) and the seconds it spends are added to an account
per chain and output kind; when the account reaches the kernel's estimated compile time
(`compile_seconds`), the kernel is compiled, synchronously, and C answers from then on, as
it does at once for that kind's later column sets. The total is then at most about twice
the better choice in hindsight (compile at once, or never), and a single fit of a few
hundred poses no longer waits seconds for GCC. Batches of `COMPILE_LARGE_BATCH` poses or
more compile at once; ``CASECAL_BACKEND=c`` compiles every batch of `COMPILE_MIN_POSES`.
numpy's translation of a Function is cached on disk too (`casecal.model._numpy_cache`): a
process that finds it there, or the kernel, builds no CasADi graph.
"""

from __future__ import annotations

import logging
import os
import threading
import time
import weakref
from typing import TYPE_CHECKING

import numpy as np

from .._threads import cores, thread_map
from ..errors import CalibrationError
from . import _native, _numpy_cache, _vectorised

if TYPE_CHECKING:
    import casadi as ca

    from .kinematics import Chain

log = logging.getLogger(__name__)

BUILDING = threading.RLock()
"""Held while a graph, Function or kernel is built: evaluations run on several threads."""

COMPILE_MIN_POSES = 200
"""Batches of at least this many poses may use compiled C (when a C compiler is present):
a cached kernel at once, else once it pays (module doc); smaller ones CasADi's evaluation."""

HOT_CALLS = 100
"""Smaller batches of one chain and output kind, in one process, after which they too use
compiled C: one kernel of every parameter column, its columns taken in numpy, so that the
many column sets of repeated fits (a study's trials) share one compile per machine."""

COMPILE_MAX_INSTRUCTIONS = 20_000
"""A one-pose Function longer than this is not compiled for batches under
`COMPILE_LARGE_BATCH` poses unless its kernel is cached: its C takes minutes to compile
(2.5 MB of C for the 103,000 instructions of an elastic humanoid's Jacobian: about 3
minutes of GCC at -O3, more than a whole fit of 250 poses by numpy, 0.17 s per call)."""

COMPILE_LARGE_BATCH = 20_000
"""Batches of at least this many poses compile even a long Function: numpy's temporaries
then cost seconds per call."""

COMPILE_SECONDS_BASE = 0.11
"""Seconds of a kernel's compile besides its instructions (`compile_seconds`)."""

COMPILE_SECONDS_PER_INSTRUCTION = 2.7e-4
"""Seconds of a kernel's compile per instruction of its one-pose Function.

With `COMPILE_SECONDS_BASE`, a least-squares line through the code generation and GCC
times (-O3, `casecal.model._native.CFLAGS`, best of two) of 18 kernels of the rr, PUMA 560
and UR5e (fk, position, the position, points and pose Jacobians: 251 to 5,306
instructions, 0.24 to 1.65 s), measured on the 2-core development machine, idle, on
2026-11-26. Every kernel lies within 25 % of the line but the rr's position (0.26 s for
0.18 s). It is an estimate for the ski-rental rule, not a promise: a busy machine compiles
slower, and Functions over `COMPILE_MAX_INSTRUCTIONS` grow faster than the line."""

PARALLEL_POSES = 8192
"""Batches of at least twice this many poses are split over threads (`thread_map`)."""


_SPENT: weakref.WeakKeyDictionary[Chain, dict[str, float]] = weakref.WeakKeyDictionary()
"""Per chain and output kind: the seconds spent evaluating batches of `COMPILE_MIN_POSES`
or more without a kernel (module doc); infinite once the kind has compiled by the rule."""

_SPENT_LOCK = threading.Lock()


def compile_seconds(instructions: int) -> float:
    """The estimated seconds to generate and compile the kernel of a one-pose Function of
    `instructions` instructions (the constants)."""
    return COMPILE_SECONDS_BASE + COMPILE_SECONDS_PER_INSTRUCTION * instructions


def spent(chain: Chain, kind: str) -> float:
    """Seconds spent on `kind` of `chain` without a kernel, towards compiling it."""
    with _SPENT_LOCK:
        return _SPENT.get(chain, {}).get(kind, 0.0)


def _charge(chain: Chain, kind: str, seconds: float) -> None:
    with _SPENT_LOCK:
        account = _SPENT.setdefault(chain, {})
        account[kind] = account.get(kind, 0.0) + seconds


def write_into(out: np.ndarray, value: np.ndarray) -> np.ndarray:
    if out.shape != value.shape or out.dtype != np.float64:
        raise ValueError(f"out must be float64 of shape {value.shape}, not {out.shape}")
    out[...] = value
    return out


class Evaluator:
    """Batched evaluation of one kind of output: compiled C when it is cached or pays (module
    doc), else numpy over the instruction list, else CasADi."""

    def __init__(self, chain: Chain, kind: str, columns: tuple[int, ...]):
        self.chain, self.kind, self.columns = chain, kind, columns
        self.shape = chain.output_shape(kind, len(columns))
        self._function = None
        self._native = None
        self._native_tried = False
        self._vectorised_fn = None
        self._vectorised_tried = False
        self._cache_looked = False  # the numpy evaluator's disk cache, looked up once

    @property
    def function(self) -> ca.Function:
        if self._function is None:
            with BUILDING:
                if self._function is None:
                    self._function = self.chain.function(self.kind, self.columns)
        return self._function

    def __call__(self, q: np.ndarray, p: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        n = q.shape[0]
        if out is not None and (
            out.shape != (n, *self.shape)
            or out.dtype != np.float64
            or not (out.flags.c_contiguous and out.flags.writeable)
        ):
            raise ValueError(
                f"out must be writeable C-contiguous float64 of shape {(n, *self.shape)}"
            )
        if self._use_native(n, p.size):
            out = np.empty((n, *self.shape)) if out is None else out
            # the C loop releases the GIL: large batches run on every core, in chunks
            parts = max(min(n // PARALLEL_POSES, cores()), 1)
            bounds = np.linspace(0, n, parts + 1).astype(int)

            def run(i: int) -> None:
                self._native(q[bounds[i] : bounds[i + 1]], p, out[bounds[i] : bounds[i + 1]])

            thread_map(run, list(range(parts)))
            return out
        vectorised = self._vectorised(n)
        started = time.perf_counter()
        if vectorised is not None:  # no kernel (yet), or no compiler: numpy over all poses
            value = vectorised(self.chain.inputs(q, p), p).reshape(n, *self.shape)
        else:
            # CasADi evaluates all N poses in one call when q has N times the expected
            # columns; its output is the horizontal concatenation of the transposed
            # per-pose outputs
            res = np.asarray(self.function(self.chain.inputs(q, p).T, p), dtype=float)
            value = res.T.copy() if len(self.shape) == 1 else res.T.reshape(n, *self.shape)
        if not self._native_tried and n >= COMPILE_MIN_POSES and backend_choice() == "auto":
            _charge(self.chain, self.kind, time.perf_counter() - started)  # towards a kernel
        return value if out is None else write_into(out, value)

    def compiled(self, q: np.ndarray, p: np.ndarray) -> np.ndarray | None:
        """The output by compiled C whatever the batch size, or None without a kernel.

        Compiles the kernel at once if need be (`HOT_CALLS` has counted the small batches).
        """
        if not self._use_native(COMPILE_MIN_POSES, p.size, at_once=True):
            return None
        out = np.empty((q.shape[0], *self.shape))
        self._native(q, p, out)
        return out

    def _key(self) -> tuple:
        """What names this evaluator's kernel and numpy code on disk."""
        structure = self.chain.structure
        key = (structure.kernel_key, self.kind, self.columns)
        if structure.by_graph:  # a user's term: what it builds, as compiled
            key += (self.chain.graph_digest,)
        return key

    def _compile_now(self, n: int, at_once: bool = False) -> bool:
        """Backend "auto", no kernel tried yet: whether to load or build it for this batch.

        A cached kernel, or a batch of `COMPILE_LARGE_BATCH` poses: yes. A Function longer
        than `COMPILE_MAX_INSTRUCTIONS`: no. Else yes `at_once`, or once numpy's seconds on
        this chain's kind reach the kernel's compile time (module doc).
        """
        if n >= COMPILE_LARGE_BATCH or _native.is_cached(self._key()):
            return True
        instructions = self._instructions()
        if instructions > COMPILE_MAX_INSTRUCTIONS:
            return False  # numpy for now; a large batch may still compile it
        if at_once or spent(self.chain, self.kind) >= compile_seconds(instructions):
            with _SPENT_LOCK:  # the kind's later column sets compile at once
                _SPENT.setdefault(self.chain, {})[self.kind] = float("inf")
            return True
        return False

    def _instructions(self) -> int:
        """The one-pose Function's instruction count: from the numpy evaluator's cache
        entry when there is one, so that a warm process builds no CasADi graph."""
        if self._function is None and self._cached_vectorised() is not None:
            return self._vectorised_fn.n_instructions
        return self.function.n_instructions()

    def _cached_vectorised(self):
        """The numpy evaluator from the disk cache (looked up once), or None."""
        if not self._vectorised_tried and not self._cache_looked:
            with BUILDING:
                if not self._vectorised_tried and not self._cache_looked:
                    found = _numpy_cache.load(self._key(), int(np.prod(self.shape)))
                    if found is not None:
                        try:
                            self._vectorised_fn = _vectorised.Vectorised.from_code(*found)
                            self._vectorised_tried = True
                        except (KeyError, TypeError, ValueError) as exc:  # verified, yet wrong
                            log.warning("cached numpy evaluator unusable (%s); rebuilding", exc)
                    self._cache_looked = True
        return self._vectorised_fn

    def _vectorised(self, n: int):
        """The numpy evaluator of the instruction list (`_vectorised`) where it serves:
        from the disk cache, else translated from the Function (and then cached)."""
        backend = backend_choice()
        if backend == "casadi" or (backend == "auto" and n < COMPILE_MIN_POSES):
            return None
        if self._cached_vectorised() is None and not self._vectorised_tried:
            with BUILDING:
                if not self._vectorised_tried:
                    try:
                        built = _vectorised.Vectorised(self.function)
                    except _vectorised.Unsupported as exc:
                        log.info("numpy evaluation unavailable (%s); using CasADi's", exc)
                    else:
                        _numpy_cache.store(
                            self._key(), built.code, built.n_out, built.n_instructions
                        )
                        self._vectorised_fn = built
                    self._vectorised_tried = True
        return self._vectorised_fn

    def _use_native(self, n: int, n_p: int, at_once: bool = False) -> bool:
        backend = backend_choice()
        if backend in ("casadi", "numpy") or (backend == "auto" and n < COMPILE_MIN_POSES):
            return False
        if not self._native_tried and backend == "auto" and not self._compile_now(n, at_once):
            return False  # numpy for now, its seconds counted towards the compile
        if not self._native_tried:
            with BUILDING:  # set "tried" only once the kernel (or None) is in place
                if not self._native_tried:
                    self._native = _native.kernel(
                        self._key(),
                        lambda: self.function,
                        n_q=self.chain.structure.n_inputs,
                        n_p=n_p,
                        n_out=int(np.prod(self.shape)),
                        joint_trig=self.chain.joint_trig,
                    )
                    self._native_tried = True
        if self._native is None and backend == "c":
            raise RuntimeError("CASECAL_BACKEND=c but no C compiler could build the kernel")
        return self._native is not None


BACKENDS = ("auto", "c", "numpy", "casadi")


def backend_choice() -> str:
    """``$CASECAL_BACKEND``: auto (C when a compiler is present, else numpy), c, numpy
    (the instruction list vectorised, `casecal.model._vectorised`) or casadi (its own)."""
    backend = os.environ.get("CASECAL_BACKEND", "auto").strip().lower() or "auto"
    if backend not in BACKENDS:
        raise CalibrationError(f"CASECAL_BACKEND={backend!r}; use one of {', '.join(BACKENDS)}")
    return backend
