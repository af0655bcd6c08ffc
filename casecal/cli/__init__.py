"""The ``casecal`` command line: one module per command (or small group of commands),
each with its own ``add_parser(sub)`` and ``run(args)``.

`casecal.cli.main` gathers them (`build_parser`, `main`); `casecal.cli.common` holds what
they share (robot loading, shared options, output checks, -q and -v),
`casecal.cli.argtypes` the argument types and `casecal.cli.writing` the writing of a fit's
files. Modules import only downwards: no command imports another, and none imports this
package's ``__init__`` or `casecal.cli.main` (tests/test_cli_package.py checks the graph).
"""

from __future__ import annotations

from .common import parse_angle, parse_length, robot_for
from .main import build_parser, main

__all__ = ["build_parser", "main", "parse_angle", "parse_length", "robot_for"]
