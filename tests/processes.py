"""Waiting on a child ``casecal`` process without guessing how long its start-up takes.

A fixed sleep before a signal races the interpreter's start-up on a loaded machine (two
test workers, another tenant): a SIGINT that lands before ``casecal._entry`` has begun
its imports is Python's, not casecal's, and the child dies with -2 instead of 130.
"""

from __future__ import annotations

import subprocess
import time
from pathlib import Path


def wait_until_loaded(proc: subprocess.Popen, library: str = "casadi", seconds: float = 120.0):
    """Return once `proc` has mapped a shared library whose path contains `library`.

    CasADi is loaded by the command's imports, inside the entry point's Ctrl-C guard, so
    a signal sent after this returns reaches casecal's own handling. Raises
    AssertionError if the process exits or `seconds` pass first.
    """
    maps = Path(f"/proc/{proc.pid}/maps")
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        assert proc.poll() is None, f"the process ended ({proc.returncode}) before loading"
        try:
            if f"/{library}" in maps.read_text():  # a path component, not any name
                return
        except OSError:  # between exit and reaping
            pass
        time.sleep(0.02)
    proc.kill()  # no child left running behind a failed test
    proc.wait()
    raise AssertionError(f"{library} not loaded within {seconds:.0f} s")
