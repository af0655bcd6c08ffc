"""Identify the PUMA 560's DH parameters from 1,000 poses: casecal against a fair numpy GN.

Compared: the full `casecal.identify` (each method, with everything it does: rounds,
identifiability, audit, covariance) against `fair_reference.fair_gauss_newton` (numpy;
frame vectors; batched normal equations, column scaling, Cholesky; one BLAS thread)
estimating the parameters casecal's default method estimates (its `estimated`), on
noise-free positions of a robot with deviations of realistic size on the identifiable
theta/d/a/alpha (0.1 mm, 0.01 deg). In-process, warmed up, all on one BLAS thread, the
contenders run interleaved A B C … for ``--repeat`` rounds (`_timing.interleave`) because
the machine is shared; CPU time (`time.process_time`, every thread) and wall time, median
and minimum, ratios to the fair reference. First calls are timed in new processes (best
of ``--first-repeat``, wall): "1st cold" with an empty kernel cache and the default
backend (a single fit answers by numpy; kernels compile once numpy's time would pay for
them), "1st warm" with the kernels compiled on disk (numpy has no cache: both are just a
new process). The steady state runs on compiled C (``CASECAL_BACKEND=c``).

Target (issue 23): the default method's full identify <= 1.5x the fair reference's CPU
(median). (Earlier targets: ipopt <= 5x.)

Run: python benchmarks/bench_identify.py [--poses 1000] [--repeat 20] [--first-repeat 3]
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
from _timing import interleave
from bench_jacobian import numpy_dh_position_jacobian
from fair_reference import fair_gauss_newton

METHODS = ("gauss-newton", "svd", "lm", "ipopt")
DEFAULT = "gauss-newton"
DH = ["theta*", "d*", "a*", "alpha*"]
ORDER = [f"{f}{i}" for i in range(1, 7) for f in ("theta", "d", "a", "alpha")]
LENGTH, ANGLE = 0.1e-3, np.deg2rad(0.01)  # deviation scales: 0.1 mm, 0.01 deg
FAIR = "fair GN"


def numpy_gauss_newton(theta, d, a, alpha, q, y, names_estimated, tol=1e-10, max_iter=20):
    """The OLD reference: deviations (SI) of `names_estimated` by plain Gauss-Newton on the
    whole 3N x k Jacobian, each step by SVD lstsq; returns (x, iterations). Slow and
    memory-hungry (see `fair_reference.fair_gauss_newton`); kept to show what it hid."""
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
    """Best wall time of the first call of `method` in `repeat` new processes, s.

    Each process uses kernel cache `cache`, or a new empty one each time when it is None.
    """
    times = []
    for _ in range(repeat):
        tmp = cache or tempfile.mkdtemp(prefix="casecal-bench-cold-")
        # cold: what a user's first call does (backend auto: numpy until compiling pays);
        # warm: the kernels this process compiled
        env = {**os.environ, "CASECAL_CACHE": tmp, "CASECAL_BACKEND": "c" if cache else "auto"}
        cmd = [sys.executable, __file__, "--child", method, "--data", data]
        out = subprocess.run(cmd, env=env, check=True, capture_output=True, text=True).stdout
        times.append(float(out.split()[-1]))
        if cache is None:
            shutil.rmtree(tmp, ignore_errors=True)
    return min(times)


def child(method, data):
    f = np.load(data)
    q, y, names = f["q"], f["y"], [str(n) for n in f["names"]]
    if method == FAIR:
        from threadpoolctl import threadpool_limits

        nominal = f["nominal"]
        with threadpool_limits(1):
            t0 = time.perf_counter()
            fair_gauss_newton(*nominal, q, y, names)
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
    parser.add_argument("--repeat", type=int, default=20)
    parser.add_argument("--first-repeat", type=int, default=3, help="new processes per first call")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    parser.add_argument("--data", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        return child(args.child, args.data)

    # this process's own cache; the cold first calls each get an empty one of their own
    cache = tempfile.mkdtemp(prefix="casecal-bench-")
    os.environ["CASECAL_CACHE"] = cache
    os.environ["CASECAL_BACKEND"] = "c"  # the steady state on compiled C from the start
    try:
        _run(args, cache)
    finally:
        shutil.rmtree(cache, ignore_errors=True)


def _run(args, cache):
    from threadpoolctl import threadpool_limits

    import casecal as cc

    robot = cc.load_robot("puma560")
    q = cc.poses.uniform(robot, args.poses, seed=0)
    fields = ("theta", "d", "a", "alpha")
    nominal = np.array([[getattr(j, f) for j in robot.joints] for f in fields])
    # the base set at the nominal robot depends on the poses and the nominal robot only
    base = cc.identify(robot, cc.simulate(robot, q), DH, method="svd").estimated
    rng = np.random.default_rng(1)
    scale = np.array([ANGLE if n.startswith(("theta", "alpha")) else LENGTH for n in base])
    truth = dict(zip(base, rng.normal(size=len(base)) * scale, strict=True))
    meas = cc.simulate(robot.with_deviations(truth), q)
    p_true = nominal.T.ravel().copy()
    p_true[[ORDER.index(n) for n in base]] += list(truth.values())
    y_np = numpy_dh_position_jacobian(*p_true.reshape(-1, 4).T, q)[0]
    fk_agree = float(np.abs(y_np - meas.positions).max())
    # what the default method estimates: the fair reference estimates the same
    names = list(cc.identify(robot, meas, DH, method=DEFAULT).estimated)
    x_true = np.array([truth.get(n, 0.0) for n in names])
    data = str(Path(cache) / "data.npz")
    np.savez(data, q=q, y=meas.positions, names=np.array(names), nominal=nominal)

    def casecal_run(m):
        cal = cc.identify(robot, meas, DH, method=m)
        return np.array([cal.deviations[n] for n in names]), cal.iterations

    runs = {FAIR: lambda: fair_gauss_newton(*nominal, q, meas.positions, names)}
    runs.update({m: lambda m=m: casecal_run(m) for m in METHODS})
    with threadpool_limits(1):
        t = interleave(runs, args.repeat, warmup=1)
    first = {
        m: (
            first_call(m, data, None, args.first_repeat),
            first_call(m, data, cache, args.first_repeat),
        )
        for m in runs
    }
    x_fair = t.samples[FAIR][0].result[0]

    print(f"PUMA 560, identify {len(names)} DH parameters ({', '.join(names)})")
    print(f"  {args.poses} uniform poses, noise-free; max |numpy FK - casecal| {fk_agree:.1e} m")
    print(t.table(FAIR, memory=False))
    print(
        "  err = max_i |x_i - x_true_i| / max_i |x_true_i|; vs fair likewise with the fair"
        " answer; first calls: best wall of new processes"
    )
    print(
        f"{'method':>12} | {'1st cold ms':>11} | {'1st warm ms':>11} | {'it':>3} | "
        f"{'err':>7} | {'vs fair':>7}"
    )
    failed = []
    for m in runs:
        x, its = t.samples[m][0].result
        err = float(np.max(np.abs(x - x_true)) / np.max(np.abs(x_true)))
        err_fair = float(np.max(np.abs(x - x_fair)) / np.max(np.abs(x_true)))
        cold, warm = first[m]
        print(
            f"{m:>12} | {cold * 1e3:11.1f} | {warm * 1e3:11.1f} | {its:3d} | {err:7.1e} | "
            f"{err_fair:7.1e}"
        )
        if m != "svd" and max(err, err_fair) > 1e-6:
            failed.append(m)
    ratio_med = t.stat(DEFAULT, "cpu") / t.stat(FAIR, "cpu")
    ratio_min = t.stat(DEFAULT, "cpu", np.min) / t.stat(FAIR, "cpu", np.min)
    print(
        f"  target: {DEFAULT} (full identify) <= 1.5x the fair reference's CPU: median "
        f"{ratio_med:.2f}x, min {ratio_min:.2f}x; ipopt <= 5x: median "
        f"{t.stat('ipopt', 'cpu') / t.stat(FAIR, 'cpu'):.2f}x"
    )
    if failed or fk_agree > 1e-12:
        raise SystemExit(f"disagree with the truth or the fair reference: {failed}")


if __name__ == "__main__":
    main()
