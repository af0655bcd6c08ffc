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

        return run(argv)
    except KeyboardInterrupt:  # during the imports; the command catches its own
        print("casecal: interrupted; nothing was written", file=sys.stderr, flush=True)
        # An interrupt that landed in code an extension module runs while it is imported
        # (PyRun_String) marks itself unhandled inside CPython even once caught here, and
        # the interpreter would then end by SIGINT (-2 to a parent, not 130). Nothing has
        # been started or written yet, so leave at once with the code.
        sys.stdout.flush()
        os._exit(130)
