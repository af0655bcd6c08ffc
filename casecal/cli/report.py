"""``casecal report``: every study, written as a PDF report with figures and tables."""

from __future__ import annotations

import argparse

from . import argtypes
from .common import Output, command, say


def add_parser(sub) -> None:
    """Register ``report`` on the subcommand action `sub`."""
    p = command(
        sub,
        "report",
        help="run every study and write the PDF report, figures and tables",
        description="Run the eleven studies (the paper's Table 1; planar arms; SCARA "
        "observability; pose count; noise; six-axis arms with Hayati's beta; optimal poses; "
        "calibrate until a target; relative measurements; compliance under gravity; an "
        "elastic humanoid tree) and write "
        "casecal-report.pdf with every figure as PNG and every table as CSV into the "
        "output folder. About 80 s on 2 idle cores (--quick: about 25 s); the first run "
        "on a machine also compiles its kernels, about 45 s more.",
    )
    p.add_argument(
        "-o",
        "--output",
        default="reports",
        metavar="DIR",
        help="output folder (default reports/). Only files an earlier report wrote there "
        "(listed in its hidden .casecal-report) are replaced; every other file is kept, and "
        "a file of yours with a name the report writes stops the report instead of being "
        "overwritten",
    )
    p.add_argument("--quick", action="store_true", help="smaller grids: fewer poses and trials")
    p.add_argument(
        "--executor",
        choices=("processes", "serial"),
        default="processes",
        help="run trials in local processes (default) or in this process",
    )
    p.add_argument(
        "--workers",
        type=argtypes.workers,
        default=None,
        help="local processes, at most four per core (default: one per core)",
    )
    p.add_argument(
        "--scheduler",
        type=argtypes.scheduler,
        metavar="ADDRESS",
        help="run trials on a dask cluster, e.g. tcp://host:8786 "
        "(needs: pip install 'casecal[distributed]')",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> None:
    """``casecal report``: every study, into the -o folder."""
    from ..report import build_report  # a leaf: matplotlib only when a report is asked for

    executor = "dask" if args.scheduler else args.executor
    build_report(  # checks its folder before any study, and makes it only when it is done
        args.output,
        quick=args.quick,
        executor=executor,
        workers=args.workers,
        scheduler=args.scheduler,
        progress=not Output.quiet,  # -q drops the studies' progress lines too
        log=lambda m: say(m, flush=True),
    )
