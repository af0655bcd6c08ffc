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
from contextlib import nullcontext

_CONTROLLER = None


def one_blas_thread():
    """A context in which BLAS (and OpenMP) pools use one thread."""
    global _CONTROLLER
    try:
        if _CONTROLLER is None:
            from threadpoolctl import ThreadpoolController

            _CONTROLLER = ThreadpoolController()  # inspecting the pools once costs ms
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
