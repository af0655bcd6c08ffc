"""The ``casecal`` command's entry point: answers Ctrl-C from the first moment.

Importing the command loads numpy, pandas and CasADi, which takes a second or more on a
loaded machine; an interrupt in that second must end as quietly as one later on.
"""

from __future__ import annotations

import os
import sys


def main(argv: list[str] | None = None) -> int:
    """Run the ``casecal`` command; exit codes as in `casecal.cli.main.main` (130: interrupted)."""
    try:
        from .cli import main as run

        code = run(argv)
        if code in (130, 143):  # interrupted, and said so: end with that code
            _forget_unhandled_interrupt(code)
        return code
    except KeyboardInterrupt:  # during the imports; the command catches its own
        print("casecal: interrupted; nothing was written", file=sys.stderr, flush=True)
        # An interrupt that landed in code an extension module runs while it is imported
        # (PyRun_String) marks itself unhandled inside CPython even once caught here, and
        # the interpreter would then end by SIGINT (-2 to a parent, not 130). Nothing has
        # been started or written yet, so leave at once with the code.
        sys.stdout.flush()
        os._exit(130)


def _forget_unhandled_interrupt(code: int) -> None:
    """Clear CPython's mark of an unhandled interrupt, which it sets when a Ctrl-C passes
    through code run by ``PyRun_String`` (an extension module importing: SciPy, pandas),
    even though the command caught it; at exit the interpreter would then kill itself by
    SIGINT (-2 to a parent instead of 130). The mark is a C global up to Python 3.11;
    where it cannot be reached, leave at once with the code (the command has unwound)."""
    import ctypes

    try:
        ctypes.c_int.in_dll(ctypes.pythonapi, "_Py_UnhandledKeyboardInterrupt").value = 0
    except (ValueError, AttributeError, OSError):
        for stream in (sys.stdout, sys.stderr):
            if stream is not None:
                try:
                    stream.flush()
                except OSError:
                    pass
        os._exit(code)
