"""The ``casecal`` command's parser and its `main`: each command's module registers its own
subcommand (``add_parser(sub)``) and runs it (``run(args)``); this module only gathers them.

Exit codes: 0 success, 2 a user error (one line on stderr), 1 a bug (traceback).
"""

from __future__ import annotations

import argparse
import logging
import sys
import warnings

from .. import __version__
from .._signals import sigterm_unwinds
from ..errors import CalibrationError, Terminated
from ..ownership import guarded
from ..textio import recording
from . import (
    calibrate_until,
    compare,
    compensate,
    convert,
    identify,
    report,
    show,
    simulate,
    validate,
)
from .common import Output, add_output_switches, one_line_warning
from .outputs import OUTPUTS, OVERWRITE_HELP, check_outputs

COMMANDS = (show, simulate, identify, calibrate_until, validate, compensate, compare, convert)
"""The command modules, in the order of ``casecal --help`` (report last)."""


class _Parser(argparse.ArgumentParser):
    """argparse with the project's error convention: one line on stderr, exit code 2."""

    def error(self, message: str):
        sys.stderr.write(f"casecal: error: {message} (see '{self.prog} --help')\n")
        sys.exit(2)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``casecal`` command."""
    parser = _Parser(
        prog="casecal",
        description="Kinematic calibration of serial robot arms: robot models with exact "
        "parameter Jacobians (CasADi), identification of DH errors from measured positions.",
        epilog="Robots are catalog names (see 'casecal robots') or paths to robot TOML, "
        "URDF, xacro or UR kinematics (.yaml) files. Lengths print in mm, angles in degrees.",
    )
    parser.add_argument("--version", action="version", version=f"casecal {__version__}")
    add_output_switches(parser, 0)
    parser.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for module in (*COMMANDS, report):
        module.add_parser(sub)
    for name, command in sub.choices.items():
        # every command that writes files may be told to replace one casecal did not write
        # (the report's folder keeps the user's files whatever it is told)
        if name != "report" and any(a.dest in OUTPUTS for a in command._actions):
            command.add_argument(  # SUPPRESS: `casecal --overwrite CMD` stands without one here
                "--overwrite", action="store_true", default=argparse.SUPPRESS, help=OVERWRITE_HELP
            )
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the ``casecal`` command; returns the exit code.

    0 success; 2 a user error, one line on stderr; 130 interrupted (Ctrl-C) and 143
    terminated (SIGTERM), one line saying what was written; 1 a bug, with its traceback.
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.quiet and args.verbose:
        parser.error("-q (quiet) and -v (verbose) ask for opposites; give one of them")
    Output.quiet, Output.verbose = bool(args.quiet), args.verbose
    level = {0: logging.WARNING, 1: logging.INFO}.get(args.verbose, logging.DEBUG)
    level = logging.ERROR if args.quiet else level
    logging.basicConfig(level=level, format="casecal: %(levelname)s: %(message)s")
    logging.getLogger("casecal").setLevel(level)  # each call's own, in one process too
    warnings.showwarning = one_line_warning
    guard = guarded(not getattr(args, "overwrite", False))  # its own files, or --overwrite
    with recording() as written, sigterm_unwinds(), guard:  # written: as each is in place
        try:
            check_outputs(args)
            args.func(args)
        except CalibrationError as exc:
            done = f"; already written: {', '.join(written)}" if written else ""
            print(f"casecal: error: {exc}{done}", file=sys.stderr)
            return 2
        except KeyboardInterrupt as exc:
            return _interrupted(exc, written)
        except BrokenPipeError:  # e.g. `casecal robots | head`
            return 0
        except OSError as exc:  # the system refused a read or write the library did not foresee
            where = f" {exc.filename!r}:" if exc.filename else ""
            print(f"casecal: error:{where} {exc.strerror or exc}", file=sys.stderr)
            return 2
        except Exception as exc:
            interrupt = _interrupt_behind(exc)
            if interrupt is None:
                raise  # a bug: its traceback, exit 1
            return _interrupted(interrupt, written)
    return 0


def _interrupted(exc: KeyboardInterrupt, written: list[str]) -> int:
    """Say that the command was interrupted and what was written; the exit code."""
    done = f"written: {', '.join(written)}" if written else "nothing was written"
    how = "terminated" if isinstance(exc, Terminated) else "interrupted"
    print(f"casecal: {how}; {done}", file=sys.stderr)
    return 143 if isinstance(exc, Terminated) else 130


def _interrupt_behind(exc: BaseException) -> KeyboardInterrupt | None:
    """The Ctrl-C (or SIGTERM) another exception was raised while handling, if any: a
    library importing when the signal came (matplotlib) may turn it into its own error."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return exc
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return None
