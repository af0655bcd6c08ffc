"""Position Jacobian of the PUMA 560 w.r.t. its 24 DH parameters at 10,000 poses.

Compared: casecal (CasADi graph, generated C, one call for all poses) against the fair
numpy reference `fair_reference.frame_position_jacobian` (each frame kept as (3, N)
vectors, updated joint by joint, columns written into a (k, 3, N) array), both on one BLAS
thread, run interleaved A B A B (`_timing.interleave`) because the machine is shared and a
block of one followed by a block of the other hands the idle moments to whichever ran
first. CPU time (every thread of the process) and wall time, median and minimum, with the
ratios to the fair reference. casecal splits batches of 16,384 poses and more over threads
(`casecal.model._evaluate.PARALLEL_POSES`): from there a row with CASECAL_THREADS=1 shows
it on one core, and CPU time is the fair measure. The first-call build time (CasADi
graph, C code generation and compilation into an empty kernel cache) is printed apart.

Without a C compiler, CasADi's own evaluation (CASECAL_BACKEND=casadi) and the numpy
evaluation of its instruction list (CASECAL_BACKEND=numpy, `casecal.model._vectorised`)
are each timed interleaved with the fair reference too (target: <= 2x its time).

The old reference of this file, `numpy_dh_position_jacobian` (an (N, 4, 4) matrix per pose
and joint), is kept for `bench_identify.numpy_gauss_newton` and shown as the "old" row.

Run: python benchmarks/bench_jacobian.py [--poses 10000] [--repeat 30]
"""

from __future__ import annotations

import argparse
import os
import shutil
import tempfile
import time
from contextlib import contextmanager

import numpy as np
from _timing import interleave
from fair_reference import column_names, frame_position_jacobian


def numpy_dh_position_jacobian(theta, d, a, alpha, q):
    """The OLD reference: standard-DH tool positions and position Jacobian w.r.t. (theta,
    d, a, alpha) per joint from (N, 4, 4) matrices per pose and joint (slow: see
    `fair_reference.frame_position_jacobian`).

    All revolute. Columns per joint i, with z_{i-1}, o_{i-1} of frame i-1, x_i, o_i of frame
    i and tool point p: dtheta = z_{i-1} x (p - o_{i-1}), dd = z_{i-1}, da = x_i,
    dalpha = x_i x (p - o_i). Returns p (N, 3) and J (N, 3, 4n), columns in the order
    theta1, d1, a1, alpha1, theta2, ...
    """
    n_poses, n = q.shape
    T = np.broadcast_to(np.eye(4), (n_poses, 4, 4)).copy()
    frames = [T]
    ca_, sa = np.cos(alpha), np.sin(alpha)
    for i in range(n):
        ct, st = np.cos(q[:, i] + theta[i]), np.sin(q[:, i] + theta[i])
        A = np.zeros((n_poses, 4, 4))
        A[:, 0, 0], A[:, 0, 1], A[:, 0, 2], A[:, 0, 3] = ct, -st * ca_[i], st * sa[i], a[i] * ct
        A[:, 1, 0], A[:, 1, 1], A[:, 1, 2], A[:, 1, 3] = st, ct * ca_[i], -ct * sa[i], a[i] * st
        A[:, 2, 1], A[:, 2, 2], A[:, 2, 3] = sa[i], ca_[i], d[i]
        A[:, 3, 3] = 1.0
        T = T @ A
        frames.append(T)
    p = T[:, :3, 3]
    cols = []
    for i in range(n):
        z_prev, o_prev = frames[i][:, :3, 2], frames[i][:, :3, 3]
        x_i, o_i = frames[i + 1][:, :3, 0], frames[i + 1][:, :3, 3]
        cols += [np.cross(z_prev, p - o_prev), z_prev, x_i, np.cross(x_i, p - o_i)]
    return p, np.stack(cols, axis=2)


@contextmanager
def env(name, value):
    old = os.environ.get(name)
    os.environ[name] = value
    try:
        yield
    finally:
        if old is None:
            os.environ.pop(name, None)
        else:
            os.environ[name] = old


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--poses", type=int, default=10_000)
    parser.add_argument("--repeat", type=int, default=30)
    args = parser.parse_args()
    from threadpoolctl import threadpool_limits

    # an empty kernel cache, so the first call pays the full build; compiled C at once
    # (backend auto would answer by numpy until compiling pays: `casecal.model._evaluate`)
    cache = tempfile.mkdtemp(prefix="casecal-bench-")
    os.environ["CASECAL_CACHE"] = cache
    os.environ["CASECAL_BACKEND"] = "c"
    try:
        with threadpool_limits(1):
            _run(args)
    finally:
        shutil.rmtree(cache, ignore_errors=True)


def _run(args):
    import casecal as cc
    from casecal.model._evaluate import PARALLEL_POSES

    robot = cc.load_robot("puma560")
    dh = ["theta*", "d*", "a*", "alpha*"]
    q = cc.poses.uniform(robot, args.poses, seed=0)
    t0 = time.perf_counter()
    J, names = robot.position_jacobian(q, dh)
    first = time.perf_counter() - t0

    nominal = [
        np.array([getattr(j, f) for j in robot.joints]) for f in ("theta", "d", "a", "alpha")
    ]
    order = column_names(len(robot.joints))
    cols = [order.index(n) for n in names]
    _, J_fair = frame_position_jacobian(*nominal, q)
    J_fair = J_fair.transpose(2, 1, 0)[:, :, cols]  # (N, 3, k) as casecal's
    scale = float(np.abs(J).max())
    agree = float(np.abs(J - J_fair).max()) / scale
    _, J_old = numpy_dh_position_jacobian(*nominal, q)
    agree = max(agree, float(np.abs(J - J_old[:, :, cols]).max()) / scale)

    def fair():
        return frame_position_jacobian(*nominal, q)

    def casecal_one_thread():
        with env("CASECAL_THREADS", "1"):
            return robot.position_jacobian(q, dh)

    runs = {
        "fair numpy": fair,
        "casecal C": lambda: robot.position_jacobian(q, dh),
    }
    if args.poses >= 2 * PARALLEL_POSES:
        runs["casecal C, 1 thread"] = casecal_one_thread
    t = interleave(runs, args.repeat, warmup=1)
    print(f"PUMA 560, position Jacobian w.r.t. {len(names)} DH parameters, {args.poses} poses")
    print(f"  max |casecal - numpy| / max |J|   {agree:.1e} (fair and old references)")
    print(f"  casecal first call (graph + C build) {first * 1e3:8.1f} ms")
    print(t.table("fair numpy", memory=False))
    per = 1e6 / args.poses
    print(
        f"  per pose (median CPU): fair {t.stat('fair numpy', 'cpu') * per:.3f} us, casecal "
        f"{t.stat('casecal C', 'cpu') * per:.3f} us"
    )
    # the old reference apart: its (N, 4, 4) temporaries change the allocator's state (pages
    # returned to the system and faulted in again) for whatever runs after it
    runs = {"fair numpy": fair, "old numpy 4x4": lambda: numpy_dh_position_jacobian(*nominal, q)}
    print(interleave(runs, max(args.repeat // 3, 3), warmup=1).table("fair numpy", memory=False))
    # without a C compiler: CasADi's own evaluation, and its instruction list run by numpy
    for backend in ("casadi", "numpy"):
        with env("CASECAL_BACKEND", backend):
            cc.model.kinematics.chain.cache_clear()
            J_b = robot.position_jacobian(q, dh)[0]
            agree = max(agree, float(np.abs(J_b - J_fair).max()) / scale)
            runs = {
                "fair numpy": fair,
                f"no compiler: {backend}": lambda: robot.position_jacobian(q, dh),
            }
            tb = interleave(runs, max(args.repeat // 3, 3), warmup=1)
        cc.model.kinematics.chain.cache_clear()
        print(tb.table("fair numpy", memory=False))
        print(f"  target: no compiler ({backend}) <= 2x the fair reference's CPU")
    if agree > 1e-12:
        raise SystemExit("the implementations disagree: the timing means nothing")


if __name__ == "__main__":
    main()
