"""Signals while casecal writes: an interrupt lands between steps, never inside one.

Python runs signal handlers in its main thread only, and any thread may receive a signal,
so these swap handlers rather than the signal mask, and do nothing off the main thread.
"""

from __future__ import annotations

import contextlib
import signal
import threading

from .errors import Terminated


@contextlib.contextmanager
def held_signals():
    """Hold Ctrl-C and SIGTERM back until the block is done: an interrupt comes after
    the block, never inside it. (Python handles signals in its main thread only, and
    any thread may receive them, so the handlers are swapped, not the signal mask.)"""
    held = (signal.SIGINT, signal.SIGTERM)
    if threading.current_thread() is not threading.main_thread() or any(
        signal.getsignal(n) is None
        for n in held  # set outside Python: cannot be put back
    ):
        yield
        return
    caught: list[int] = []
    previous = {}
    try:
        for signum in held:  # inside the try: whatever was swapped is put back
            previous[signum] = signal.signal(signum, lambda n, _: caught.append(n))
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
        if caught:  # now as it would have been handled (the first: both mean stop)
            handler = previous[caught[0]]
            if callable(handler):
                handler(caught[0], None)
            elif handler == signal.SIG_DFL:
                signal.raise_signal(caught[0])


@contextlib.contextmanager
def sigterm_unwinds():
    """SIGTERM (a supervisor's ``kill``) unwinds like Ctrl-C inside the block, raising
    `casecal.errors.Terminated`: temporary files are removed, workers stopped, and the
    command says what was written. Only from the main thread, over the default action."""
    if (
        threading.current_thread() is not threading.main_thread()
        or signal.getsignal(signal.SIGTERM) is not signal.SIG_DFL
    ):
        yield
        return

    def unwind(signum, frame):
        raise Terminated("terminated (SIGTERM)")

    signal.signal(signal.SIGTERM, unwind)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
