"""Calibrate the same arm as a DH table and as a URDF (issue 11): time ratio URDF / DH.

The KUKA KR 16-2 of casecal's catalog, written as a URDF by ``cc.save_robot`` and read back:
the same chain, parameterised per joint origin (7 parameters a joint instead of 4). Data:
an unknown base 2 m away, a marker off the flange, 0.5 mm / 0.5 mrad deviations on the DH
rows, 0.02 mm noise. Both fits use ``parameters="all"`` and the default method; each repeat
is a new noise realisation. Printed: median seconds of each and the ratio (target <= 2).

Run: python benchmarks/bench_urdf.py [--poses 1000 5000] [--repeat 5]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

import casecal as cc


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--poses", type=int, nargs="+", default=[1000, 5000])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    marker = [[0.05, 0.02, 0.1]]
    dh = cc.load_robot("kr16_2").with_points(marker)
    with tempfile.TemporaryDirectory() as folder:
        cc.save_robot(dh, Path(folder) / "kr16_2.urdf")
        urdf = cc.load_robot(Path(folder) / "kr16_2.urdf").with_points(marker)
    rng = np.random.default_rng(0)
    truth = {n: rng.normal() * 5e-4 for n in dh.parameter_names if n[0] in "tad"}
    truth.update(base_x=2.0, base_y=-0.5, base_rz=1.0)
    true = dh.with_deviations(truth)
    print(f"{'poses':>6} {'DH (s)':>8} {'URDF (s)':>9} {'ratio':>6}  estimated DH / URDF")
    for n in args.poses:
        q = cc.poses.uniform(dh, n, seed=1)
        times = {"dh": [], "urdf": []}
        counts = {}
        for r in range(args.repeat + 1):  # the first round compiles and warms up
            meas = cc.simulate(true, q, noise=2e-5, seed=100 + r)
            for key, nominal in (("dh", dh), ("urdf", urdf)):
                t0 = time.perf_counter()
                cal = cc.identify(nominal, meas, "all")
                if r:
                    times[key].append(time.perf_counter() - t0)
                counts[key] = (len(cal.estimated), cal.success)
        a, b = np.median(times["dh"]), np.median(times["urdf"])
        print(
            f"{n:>6} {a:>8.3f} {b:>9.3f} {b / a:>6.2f}  "
            f"{counts['dh'][0]} / {counts['urdf'][0]} "
            f"(success {counts['dh'][1]} / {counts['urdf'][1]})"
        )


if __name__ == "__main__":
    main()
