"""The ``casecal`` command's entry point: answers Ctrl-C from the first moment.

Importing the command loads numpy, pandas and CasADi, which takes a second or more on a
loaded machine; an interrupt in that second must end as quietly as one later on.
"""

from __future__ import annotations

import sys


def main(argv: list[str] | None = None) -> int:
    """Run the ``casecal`` command; exit codes as in `casecal.cli.main.main` (130: interrupted)."""
    try:
        from .cli import main as run

        return run(argv)
    except KeyboardInterrupt:  # during the imports; the command catches its own
        print("casecal: interrupted; nothing was written", file=sys.stderr)
        return 130
