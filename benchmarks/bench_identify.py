"""Identify the PUMA 560's DH parameters from 1,000 uniform poses with every casecal method.

All identifiable DH parameters: the base set casecal estimates from theta*, d*, a*, alpha*
(the rest are held at nominal, also in the truth, so the truth of the base set is exact).
Noise-free positions of a robot with deviations of realistic size on each (0.1 mm, 0.01 deg).
Each method is timed beside a plain numpy Gauss-Newton reference (vectorised FK, geometric
Jacobian columns, column scaling, lstsq, full steps) in the same run, because the machine is
shared and a lone time means little. First calls are timed in new processes (best of a few):
"1st cold" with an empty kernel cache (CasADi graph, C generation and compilation inside the
call), "1st warm" with the kernels already compiled on disk (numpy has no cache: both are just
a new process). Targets: gauss-newton no slower than numpy (first call included), ipopt at
most 5x numpy.

Run: python benchmarks/bench_identify.py [--poses 1000] [--repeat 10] [--first-repeat 3]
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from bench_jacobian import best_time, numpy_dh_position_jacobian

METHODS = ("svd", "gauss-newton", "lm", "ipopt")
DH = ["theta*", "d*", "a*", "alpha*"]
ORDER = [f"{f}{i}" for i in range(1, 7) for f in ("theta", "d", "a", "alpha")]
LENGTH, ANGLE = 0.1e-3, np.deg2rad(0.01)  # deviation scales: 0.1 mm, 0.01 deg


def numpy_gauss_newton(theta, d, a, alpha, q, y, names_estimated, tol=1e-10, max_iter=20):
    """Deviations (SI) of `names_estimated` by plain Gauss-Newton; returns (x, iterations)."""
    idx = [ORDER.index(n) for n in names_estimated]
    p0 = np.stack([theta, d, a, alpha], axis=1).ravel()  # ORDER layout
    x = np.zeros(len(idx))
    for it in range(1, max_iter + 1):
        p = p0.copy()
        p[idx] += x
        f, J = numpy_dh_position_jacobian(p[0::4], p[1::4], p[2::4], p[3::4], q)
        J = J[:, :, idx].reshape(-1, len(idx))
        norms = np.linalg.norm(J, axis=0)
        z = np.linalg.lstsq(J / norms, (y - f).ravel(), rcond=None)[0]  # scaled step
        x = x + z / norms
        if np.linalg.norm(z) <= tol * (np.linalg.norm(x * norms) + tol):
            return x, it
    return x, max_iter


def first_call(method, data, cache, repeat):
    """Best time of the first call of `method` in `repeat` new processes, s.

    Each process uses kernel cache `cache`, or a new empty one each time when it is None.
    """
    times = []
    for _ in range(repeat):
        tmp = cache or tempfile.mkdtemp(prefix="casecal-bench-cold-")
        env = {**os.environ, "CASECAL_CACHE": tmp}
        cmd = [sys.executable, __file__, "--child", method, "--data", data]
        out = subprocess.run(cmd, env=env, check=True, capture_output=True, text=True).stdout
        times.append(float(out.split()[-1]))
        if cache is None:
            shutil.rmtree(tmp, ignore_errors=True)
    return min(times)


def child(method, data):
    f = np.load(data)
    q, y, names = f["q"], f["y"], [str(n) for n in f["names"]]
    if method == "numpy":
        nominal = f["nominal"]
        t0 = time.perf_counter()
        numpy_gauss_newton(*nominal, q, y, names)
    else:
        import casecal as cc

        robot = cc.load_robot("puma560")
        meas = cc.Measurements(q=q, positions=y, sigma=0.0)
        t0 = time.perf_counter()
        cc.identify(robot, meas, DH, method=method)
    print(time.perf_counter() - t0)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--poses", type=int, default=1000)
    parser.add_argument("--repeat", type=int, default=10)
    parser.add_argument("--first-repeat", type=int, default=3, help="new processes per first call")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    parser.add_argument("--data", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        return child(args.child, args.data)

    # this process's own cache; the cold first calls each get an empty one of their own
    cache = tempfile.mkdtemp(prefix="casecal-bench-")
    os.environ["CASECAL_CACHE"] = cache
    import casecal as cc

    robot = cc.load_robot("puma560")
    q = cc.poses.uniform(robot, args.poses, seed=0)
    fields = ("theta", "d", "a", "alpha")
    nominal = np.array([[getattr(j, f) for j in robot.joints] for f in fields])
    # the base set casecal estimates depends on the poses and the nominal robot only
    names = cc.identify(robot, cc.simulate(robot, q), DH, method="svd").estimated
    rng = np.random.default_rng(1)
    scale = np.array([ANGLE if n.startswith(("theta", "alpha")) else LENGTH for n in names])
    truth = rng.normal(size=len(names)) * scale
    meas = cc.simulate(robot.with_deviations(dict(zip(names, truth, strict=True))), q)
    p_true = nominal.T.ravel().copy()
    p_true[[ORDER.index(n) for n in names]] += truth
    y_np = numpy_dh_position_jacobian(*p_true.reshape(-1, 4).T, q)[0]
    fk_agree = float(np.abs(y_np - meas.positions).max())
    data = str(Path(cache) / "data.npz")
    np.savez(data, q=q, y=meas.positions, names=np.array(names), nominal=nominal)

    def casecal_run(m):
        cal = cc.identify(robot, meas, DH, method=m)
        return np.array([cal.deviations[n] for n in names]), cal.iterations

    runs = {"numpy": lambda: numpy_gauss_newton(*nominal, q, meas.positions, names)}
    runs.update({m: lambda m=m: casecal_run(m) for m in METHODS})
    rows = {}
    for m, run in runs.items():
        cold = first_call(m, data, None, args.first_repeat)
        warm = first_call(m, data, cache, args.first_repeat)
        x, its = run()
        best, median = best_time(run, args.repeat)
        rows[m] = (cold, warm, best, median, x, its)
    x_np, t_np = rows["numpy"][4], rows["numpy"][2]

    print(f"PUMA 560, identify {len(names)} DH parameters ({', '.join(names)})")
    print(f"  {args.poses} uniform poses, noise-free; max |numpy FK - casecal| {fk_agree:.1e} m")
    print("  rel err = max_i |x_i - x_true_i| / |x_true_i|; ratios are to numpy's best time")
    print(
        f"{'method':>12} | {'1st cold ms':>11} | {'1st warm ms':>11} | {'best ms':>8} | "
        f"{'median ms':>9} | {'ratio':>7} | {'it':>3} | {'rel err':>7} | {'vs numpy':>8}"
    )
    failed = []
    for m, (cold, warm, best, median, x, its) in rows.items():
        err = float(np.max(np.abs(x - truth) / np.abs(truth)))
        err_np = float(np.max(np.abs(x - x_np) / np.abs(truth)))
        print(
            f"{m:>12} | {cold * 1e3:11.1f} | {warm * 1e3:11.1f} | {best * 1e3:8.2f} | "
            f"{median * 1e3:9.2f} | {best / t_np:6.2f}x | {its:3d} | {err:7.1e} | "
            f"{err_np:8.1e}"
        )
        if m != "svd" and max(err, err_np) > 1e-6:
            failed.append(m)
    gn, ipopt = rows["gauss-newton"], rows["ipopt"]
    print(
        f"  targets: gauss-newton <= numpy: best {gn[2] / t_np:.2f}x, 1st cold "
        f"{gn[0] / rows['numpy'][0]:.1f}x, 1st warm {gn[1] / rows['numpy'][1]:.1f}x; "
        f"ipopt <= 5x numpy: best {ipopt[2] / t_np:.2f}x"
    )
    if failed or fk_agree > 1e-12:
        raise SystemExit(f"disagree with the truth or numpy: {failed}; timing means nothing")


if __name__ == "__main__":
    main()
