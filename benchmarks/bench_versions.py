"""Is a serial arm's fit as fast as before a change? The same fit timed at two revisions.

The trees-and-sensors redesign (issue 21) reshaped the model and the fitting path; a 6R
arm must not pay for it. This benchmark fits the same data with casecal at two git
revisions (default: the working tree against 750a26e, the commit before the redesign),
each in its own process with its own copy of the package, interleaved (A B A B …) so that
the shared machine's busy moments fall on both. Each process builds the data from a fixed
seed, warms up (the first call compiles or loads the kernels: the kernels' cache key of a
serial robot is the same at both revisions, so they share the compiled kernels), checks
that both revisions agree on the answer, then times `identify` (the default method, the
default parameters) and prints CPU and wall seconds. One BLAS thread in every process.

Reported: per case, median and minimum CPU and wall time per revision, their ratio
(new / old), and the machine's load before and after.

Run: python benchmarks/bench_versions.py [--old 750a26e] [--poses 1000 100000] [--repeat 7]
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
ROBOT = "puma560"
LENGTH, ANGLE = 0.5e-3, np.deg2rad(0.05)  # deviation scales of the simulated truth
NOISE = 20e-6  # m, a laser tracker's


def child(poses: int, repeat: int) -> None:
    """Time `identify` in this process (the casecal on sys.path); print JSON on stdout."""
    import casecal as cc

    robot = cc.load_robot(ROBOT)
    q = cc.poses.uniform(robot, poses, seed=0)
    rng = np.random.default_rng(1)
    # the default parameters are the paper's (theta, d, a; alpha held): a truth inside them
    names = [n for n in robot.parameter_names if n.rstrip("0123456789") in ("theta", "d", "a")]
    scale = [ANGLE if n.startswith("theta") else LENGTH for n in names]
    true = robot.with_deviations(dict(zip(names, rng.normal(size=len(names)) * scale, strict=True)))
    meas = cc.simulate(true, q, NOISE, seed=2)
    cal = cc.identify(robot, meas)  # warm-up: kernels compiled or loaded
    runs = []
    for _ in range(repeat):
        c0, w0 = time.process_time(), time.perf_counter()
        cal = cc.identify(robot, meas)
        runs.append((time.process_time() - c0, time.perf_counter() - w0))
    check = cc.poses.uniform(robot, 200, seed=3)
    error = np.linalg.norm(cal.robot.position(check) - true.position(check), axis=-1)
    out = {"runs": runs, "status": cal.status, "held_out_mm": float(error.mean() * 1e3)}
    print(json.dumps(out))


def unpack(revision: str, into: Path) -> Path:
    """The package at `revision` (its `casecal/` folder) unpacked under `into`."""
    archive = into / "src.tar"
    with open(archive, "wb") as f:
        subprocess.run(
            ["git", "-C", str(REPO), "archive", revision, "casecal"], stdout=f, check=True
        )
    with tarfile.open(archive) as tar:
        tar.extractall(into, filter="data")
    archive.unlink()
    return into


def run(path: Path, poses: int, repeat: int) -> dict:
    env = {
        **os.environ,
        "PYTHONPATH": str(path),
        "OMP_NUM_THREADS": "1",
        "OPENBLAS_NUM_THREADS": "1",
        "MKL_NUM_THREADS": "1",
    }
    cmd = [
        sys.executable,
        str(Path(__file__).resolve()),
        "--child",
        str(poses),
        "--repeat",
        str(repeat),
    ]
    done = subprocess.run(cmd, env=env, check=True, capture_output=True, text=True, cwd=path)
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--old", default="750a26e", help="the revision to compare with")
    parser.add_argument("--poses", type=int, nargs="+", default=[1000, 100000])
    parser.add_argument("--repeat", type=int, default=7, help="timed fits per process")
    parser.add_argument("--rounds", type=int, default=3, help="A B rounds per case")
    parser.add_argument("--child", type=int, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        return child(args.child, args.repeat)

    # killed, the temporary copy of the old package is removed all the same
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))
    print(f"load average before: {' '.join(f'{v:.2f}' for v in os.getloadavg())}")
    with tempfile.TemporaryDirectory(prefix="casecal-bench-versions-") as tmp:
        old = unpack(args.old, Path(tmp))
        paths = {"new": REPO, "old": old}
        print(f"{ROBOT}, default method and parameters, σ = {NOISE * 1e6:.0f} µm; new = {REPO}")
        print(f"old = {args.old}; {args.rounds} rounds × {args.repeat} fits per revision")
        header = f"{'poses':>7} | {'rev':>3} | {'CPU med s':>9} | {'CPU min s':>9} | "
        print(header + f"{'wall med s':>10} | {'wall min s':>10} | held-out mm")
        for poses in args.poses:
            times: dict[str, list] = {"new": [], "old": []}
            checks = {}
            for _ in range(args.rounds):
                for rev in ("old", "new"):  # interleaved
                    out = run(paths[rev], poses, args.repeat)
                    times[rev] += out["runs"]
                    checks[rev] = out
            stats = {}
            for rev in ("old", "new"):
                t = np.array(times[rev])
                stats[rev] = (np.median(t, axis=0), t.min(axis=0))
                med, low = stats[rev]
                print(
                    f"{poses:7d} | {rev:>3} | {med[0]:9.3f} | {low[0]:9.3f} | {med[1]:10.3f} | "
                    f"{low[1]:10.3f} | {checks[rev]['held_out_mm']:.4f} ({checks[rev]['status']})"
                )
            ratio = stats["new"][0] / stats["old"][0]
            ratio_min = stats["new"][1] / stats["old"][1]
            print(
                f"{poses:7d} | new/old CPU median {ratio[0]:.2f}, min {ratio_min[0]:.2f}; "
                f"wall median {ratio[1]:.2f}, min {ratio_min[1]:.2f}"
            )
            gap = abs(checks["new"]["held_out_mm"] - checks["old"]["held_out_mm"])
            if gap > 1e-6:
                print(f"  the revisions disagree: held-out {gap:.2e} mm apart; timing means little")
    print(f"load average after: {' '.join(f'{v:.2f}' for v in os.getloadavg())}")


if __name__ == "__main__":
    main()
