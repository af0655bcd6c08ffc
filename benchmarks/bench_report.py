"""The main job's time at two revisions: `casecal report` in new processes, interleaved.

Each run is a new process running ``casecal report`` (``--quick`` unless ``--full``) into
a folder of its own, with the package of its revision (the working tree, or ``--old``
unpacked from git as `bench_versions.unpack` does) and the kernel cache of this machine
(``$CASECAL_CACHE`` or ``~/.cache/casecal``): the C kernels' key is the same at both
revisions where the model did not change, so they share what is compiled. Before the
timed rounds each revision runs once untimed, which fills the cache as a user's first
report does. The runs alternate A B A B for ``--repeat`` rounds (`_timing.interleave`);
CPU is every process's user + system time, the report's workers included
(RUSAGE_CHILDREN), and wall time the whole run's; medians and minimums, the load printed.

Run: python benchmarks/bench_report.py [--old REV] [--repeat 2] [--full] [--serial]
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
from pathlib import Path

from _timing import Command, interleave, load, report
from bench_versions import REPO, unpack


def child(out: str, full: bool, serial: bool) -> None:
    from casecal.cli import main

    argv = ["report", "-q", "-o", out, *([] if full else ["--quick"])]
    argv += ["--executor", "serial"] if serial else []
    code = main(argv)
    if code:
        raise SystemExit(code)
    import casecal

    report(package=str(Path(casecal.__file__).parent))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--old", default="HEAD~1", help="the revision to compare with")
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--full", action="store_true", help="the whole report, not --quick")
    parser.add_argument("--serial", action="store_true", help="one process, no workers")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        return child(args.child, args.full, args.serial)
    folder = Path(tempfile.mkdtemp(prefix="casecal-bench-report-"))
    try:
        (folder / "old").mkdir()
        old = unpack(args.old, folder / "old")
        runs = {}
        for name, path in (("working tree", REPO), (args.old, old)):
            out = folder / f"out-{len(runs)}"
            argv = [sys.executable, str(Path(__file__).resolve()), "--child", str(out)]
            argv += ["--full"] * args.full + ["--serial"] * args.serial
            runs[name] = Command(argv, {"PYTHONPATH": str(path)})
        mode = ("full" if args.full else "--quick") + (", serial" if args.serial else "")
        print(f"casecal report ({mode}), working tree vs {args.old}; load before {load()}")
        t = interleave(runs, args.repeat, warmup=1)
        print(t.table(args.old, memory=False))
        for name in runs:
            print(f"  {name}: package {t.samples[name][0].result['package']}")
        print(f"  load after {load()}")
    finally:
        shutil.rmtree(folder, ignore_errors=True)


if __name__ == "__main__":
    main()
