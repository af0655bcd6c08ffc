"""The command line of the scripts in studies/: one study, alone."""

from __future__ import annotations

import argparse
from pathlib import Path

from . import run_studies, study_runner


def main(name: str, doc: str) -> None:
    """Parse ``[--quick] [-o DIR] [--serial]`` and run study `name`, printing what it wrote."""
    parser = argparse.ArgumentParser(description=doc.split("\n")[0])
    parser.add_argument(
        "-o", "--output", default="reports", help="output folder (default reports/)"
    )
    parser.add_argument("--quick", action="store_true", help="smaller grid")
    parser.add_argument("--serial", action="store_true", help="no worker processes")
    args = parser.parse_args()
    with study_runner("serial" if args.serial else "processes") as run:
        (result,) = run_studies([name], Path(args.output), args.quick, run, log=print)
    for item in [*result.tables, *result.figures]:
        print(f"wrote {item.path}")
