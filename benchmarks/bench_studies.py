"""Does the study engine use every core? A study serially on one thread, then on 1, 2, …
local workers.

8 catalog robots × 32 Monte Carlo trials (seeds) of a pose-count cell (100 uniform poses,
sigma 0.02 mm, Gauss-Newton, theta/a/d): 256 independent identifications, spread by
`casecal.studies.run_study` over local worker processes (one BLAS thread and no kernel
threads each: `casecal.studies.executor._worker_start`). Each process run starts its own
workers, so their start-up is included.

Compared: each worker count against the serial run in this process under the same limits
as a worker (one BLAS thread by `threadpoolctl.threadpool_limits(1)`, CASECAL_THREADS=1),
so the speed-up is honest: a serial baseline on the default threads (a BLAS thread per
core, spinning on a busy machine) once made 2 workers on 2 cores look 2.48x faster. With
``--repeat`` above 1 the serial and process runs alternate (`_timing.interleave`). Prints
wall and CPU (this process plus its reaped workers) per run, median and min, and the
speed-up (serial wall / wall, medians). The rows must be identical whatever the worker
count and in the serial run (checked). A last line measures what the machine allows right
now: the speed-up of the largest count of pure-Python CPU-bound processes run together.

Target (issue 23): a study of 256 trials speeds up >= 0.8x the worker count over the
one-thread serial run, up to the cores present.

Run: python benchmarks/bench_studies.py [--trials 32] [--poses 100] [--workers 1 2 4]
     [--repeat 1]
"""

from __future__ import annotations

import argparse
import os
import resource
import time

import numpy as np
import pandas as pd
from _timing import interleave

ROBOTS = ("puma560", "scorbot", "kr15_2", "irb120", "ur5e", "rx90b", "lrmate200id", "kr16_2")
SERIAL = "serial, 1 thread"


def children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _spin(n: int) -> int:
    s = 0
    for i in range(n):
        s += i * i
    return s


def machine_parallelism(workers: int, n: int = 5_000_000) -> float:
    """How many of `workers` CPU-bound processes the machine runs at once right now: their
    speed-up over one after another (`workers` on idle cores). On a machine shared with
    other work this bounds what any study engine could show."""
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(workers) as pool:
        list(pool.map(_spin, [1000] * workers))  # started
        t0 = time.perf_counter()
        list(pool.map(_spin, [n] * workers))
        together = time.perf_counter() - t0
    t0 = time.perf_counter()
    _spin(n)
    alone = time.perf_counter() - t0
    return workers * alone / together


def main():
    from threadpoolctl import threadpool_limits

    from casecal._threads import cores
    from casecal.studies.engine import Grid, run_study

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--trials", type=int, default=32)
    parser.add_argument("--poses", type=int, default=100)
    parser.add_argument("--workers", type=int, nargs="+", default=None)
    parser.add_argument("--repeat", type=int, default=1, help="interleaved rounds")
    args = parser.parse_args()
    n_cores = cores()
    counts = args.workers or sorted({1, 2, n_cores} | {w for w in (4, 8, 16) if w < n_cores})
    grid = Grid(
        robots=ROBOTS,
        poses=(args.poses,),
        noise=(0.02e-3,),
        methods=("gauss-newton",),
        schedules=("uniform",),
        trials=args.trials,
    )
    run_study(Grid(robots=ROBOTS, poses=(args.poses,), trials=1), executor="serial")  # kernels

    def serial():
        old = os.environ.get("CASECAL_THREADS")
        os.environ["CASECAL_THREADS"] = "1"  # as in a worker: no kernel threads
        try:
            with threadpool_limits(1):
                return run_study(grid, executor="serial"), 0.0
        finally:
            if old is None:
                os.environ.pop("CASECAL_THREADS")
            else:
                os.environ["CASECAL_THREADS"] = old

    def processes(w):
        c0 = children_cpu()
        # workers=1 would run in this process (`Executor.map`): two or more are processes
        df = run_study(grid, executor="processes", workers=w)
        return df, children_cpu() - c0

    runs = {SERIAL: serial}
    runs.update({f"{w} worker{'s' * (w > 1)}": (lambda w=w: processes(w)) for w in counts})
    t = interleave(runs, args.repeat)

    print(f"{grid.size} trials ({len(ROBOTS)} robots x {args.trials} seeds, {args.poses} poses)")
    print(
        f"{os.cpu_count()} CPUs, {n_cores} usable; {args.repeat} interleaved round(s); load "
        f"average before {t.load_before}, after {t.load_after}"
    )
    print(
        f"{'':<16} | {'wall s med':>10} {'min':>7} | {'CPU s med':>9} | {'speed-up':>8} | "
        f"{'per worker':>10}"
    )
    reference = None
    base = t.stat(SERIAL, "wall")
    for name, samples in t.samples.items():
        for s in samples:
            rows = s.result[0].drop(columns=["wall_time_s"])
            if reference is None:
                reference = rows
            else:
                pd.testing.assert_frame_equal(rows, reference)  # same answers, any way run
        wall = t.stat(name, "wall")
        cpu = float(np.median([s.cpu + s.result[1] for s in samples]))
        w = 1 if name == SERIAL else int(name.split()[0])
        print(
            f"{name:<16} | {wall:10.2f} {t.stat(name, 'wall', np.min):7.2f} | {cpu:9.2f} | "
            f"{base / wall:7.2f}x | {base / wall / w:9.2f}x"
        )
    probe = machine_parallelism(max(counts))
    print(
        f"  machine check after the runs: {max(counts)} CPU-bound processes ran {probe:.2f}x "
        f"faster together than one after another ({max(counts)}x on idle cores)"
    )
    print(
        "  speed-up: serial wall / wall (medians); target >= 0.8x the worker count up to the"
        " cores present. 1 worker runs in this process (`Executor.map`), on casecal's default"
        " threads."
    )


if __name__ == "__main__":
    main()
