"""Does the study engine use every core? A scaled-up study with 1, 2, … all local workers.

8 catalog robots × 32 Monte Carlo trials (seeds) of a pose-count cell (100 uniform poses,
sigma 0.02 mm, Gauss-Newton, theta/a/d): 256 independent identifications, spread by
`casecal.studies.run_study` over local worker processes (one BLAS thread each). Each run
starts its own workers, so their start-up is included. Prints the wall time per worker
count and the speed-up over one worker, which should be at least 0.8x the worker count up
to the cores present. The rows must be identical whatever the worker count (checked).

Run: python benchmarks/bench_studies.py [--trials 32] [--poses 100] [--workers 1 2 4]
"""

from __future__ import annotations

import argparse
import os
import time

import pandas as pd

ROBOTS = ("puma560", "scorbot", "kr15_2", "irb120", "ur5e", "rx90b", "lrmate200id", "kr16_2")


def main():
    from casecal._threads import cores
    from casecal.studies.engine import Grid, run_study

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--trials", type=int, default=32)
    parser.add_argument("--poses", type=int, default=100)
    parser.add_argument("--workers", type=int, nargs="+", default=None)
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
    print(f"{grid.size} trials ({len(ROBOTS)} robots x {args.trials} seeds, {args.poses} poses)")
    print(f"{os.cpu_count()} CPUs, {n_cores} usable")
    print(f"{'workers':>7} | {'wall s':>7} | {'speed-up':>8} | {'per worker':>10}")
    base, reference = None, None
    for w in counts:
        t0 = time.perf_counter()
        df = run_study(grid, executor="processes", workers=w)
        t = time.perf_counter() - t0
        rows = df.drop(columns=["wall_time_s"])
        if reference is None:
            base, reference = t, rows
        else:
            pd.testing.assert_frame_equal(rows, reference)  # same answers, any worker count
        print(f"{w:7d} | {t:7.2f} | {base / t:7.2f}x | {base / t / w:9.2f}x")
    print("  target: speed-up >= 0.8x the worker count up to the cores present")


if __name__ == "__main__":
    main()
