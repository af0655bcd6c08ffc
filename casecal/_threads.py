"""BLAS threads under control.

OpenBLAS and MKL start as many threads as there are cores for every factorisation, and on
a machine busy with other work those threads spin waiting for each other: a 600 × 15 QR
that takes 0.07 ms on one thread took 2 ms with two threads beside two busy processes, and
an identification 4× its idle time. casecal's factorisations are small (k × k, or tall
with a few dozen columns), where one thread is as fast when idle and far faster when not,
so `identify` runs with one BLAS thread, and study workers do too.
"""

from __future__ import annotations

import functools
import os
import threading
from concurrent.futures import ThreadPoolExecutor
from contextlib import nullcontext

_CONTROLLER = None


def one_blas_thread():
    """A context in which BLAS (and OpenMP) pools use one thread."""
    global _CONTROLLER
    try:
        if _CONTROLLER is None:
            import scipy.linalg  # noqa: F401  its own OpenBLAS, loaded before inspection
            from threadpoolctl import ThreadpoolController

            # inspecting the pools costs ms: once, after every BLAS casecal calls is loaded
            # (a library loaded later would keep a thread per core and spin)
            _CONTROLLER = ThreadpoolController()
        return _CONTROLLER.limit(limits=1)
    except ImportError:  # threadpoolctl is a dependency; a broken install still works
        return nullcontext()


def with_one_blas_thread(func):
    """Decorate `func` to run with one BLAS thread (signature and docstring kept)."""

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        with one_blas_thread():
            return func(*args, **kwargs)

    return wrapper


def cores() -> int:
    """Cores this process may run on (``$CASECAL_THREADS`` caps it), at least 1."""
    try:
        n = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # not on Linux
        n = os.cpu_count() or 1
    cap = os.environ.get("CASECAL_THREADS", "")  # 0 as 1: no threads
    return max(1, min(n, int(cap))) if cap.isdigit() else max(n, 1)


_POOL: tuple[int, ThreadPoolExecutor] | None = None  # (pid, pool): a fork has no threads


def thread_map(func, items: list) -> list:
    """``[func(item) for item in items]`` on up to `cores` threads.

    For work that releases the GIL (compiled kernels called through ctypes, LAPACK through
    scipy): each item runs single-threaded, so the threads never wait on each other as
    BLAS's own do, and a busy machine costs no more than the serial loop. The pool is
    created on first use and kept (threads only, no memory held between calls).
    """
    pool = _pool() if len(items) > 1 else None
    if pool is None:
        return [func(item) for item in items]
    return list(pool.map(functools.partial(_inside, func), items))


def _pool() -> ThreadPoolExecutor | None:
    """The shared thread pool, or None where threads would not help (one core, or a pool
    thread itself, which must not wait on the pool: deadlock)."""
    global _POOL
    if cores() < 2 or getattr(_INSIDE, "pool", False):
        return None
    with _CREATING:
        if _POOL is None or _POOL[0] != os.getpid():
            _POOL = (os.getpid(), ThreadPoolExecutor(cores(), thread_name_prefix="casecal"))
        return _POOL[1]


_CREATING = threading.Lock()


_INSIDE = threading.local()


def _inside(func, item):
    _INSIDE.pool = True
    return func(item)
