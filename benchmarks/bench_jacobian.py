"""Position Jacobian of the PUMA 560 w.r.t. its 24 DH parameters at 10,000 poses.

casecal (CasADi graph, generated C, one call for all poses) against a plain vectorised numpy
implementation of the same Jacobian (the textbook geometric columns, e.g. Hollerbach et al.),
timed in the same run because the machine is shared and a lone time means little. The
first-call build time (CasADi graph, C code generation and compilation into an empty cache)
is printed apart from the steady-state time. Without a C compiler, CasADi's own evaluation
and the numpy evaluation of its instruction list (`casecal.model._vectorised`) are timed too.

Run: python benchmarks/bench_jacobian.py [--poses 10000] [--repeat 30]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time

import numpy as np


def numpy_dh_position_jacobian(theta, d, a, alpha, q):
    """Standard-DH tool positions and position Jacobian w.r.t. (theta, d, a, alpha) per joint.

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


def best_time(fn, repeat):
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times), float(np.median(times))


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--poses", type=int, default=10_000)
    parser.add_argument("--repeat", type=int, default=30)
    args = parser.parse_args()

    # an empty kernel cache, so the first call pays the full build
    os.environ["CASECAL_CACHE"] = tempfile.mkdtemp(prefix="casecal-bench-")
    import casecal as cc

    robot = cc.load_robot("puma560")
    dh = ["theta*", "d*", "a*", "alpha*"]
    q = cc.poses.uniform(robot, args.poses, seed=0)
    t0 = time.perf_counter()
    J, names = robot.position_jacobian(q, dh)
    first = time.perf_counter() - t0

    joints = robot.joints
    theta = np.array([j.theta for j in joints])
    d = np.array([j.d for j in joints])
    a = np.array([j.a for j in joints])
    alpha = np.array([j.alpha for j in joints])
    _, J_np = numpy_dh_position_jacobian(theta, d, a, alpha, q)
    order = [f"{f}{i}" for i in range(1, 7) for f in ("theta", "d", "a", "alpha")]
    J_np = J_np[:, :, [order.index(n) for n in names]]
    agree = float(np.abs(J - J_np).max())

    t_cc, m_cc = best_time(lambda: robot.position_jacobian(q, dh), args.repeat)
    t_np, m_np = best_time(lambda: numpy_dh_position_jacobian(theta, d, a, alpha, q), args.repeat)
    per = 1e6 / args.poses
    print(f"PUMA 560, position Jacobian w.r.t. {len(names)} DH parameters, {args.poses} poses")
    print(f"  max |casecal - numpy|            {agree:.1e} m (per m or rad)")
    print(f"  casecal first call (graph+C build) {first * 1e3:8.1f} ms")
    print(f"  casecal   best {t_cc * per:6.3f} us/pose  (median {m_cc * per:6.3f})")
    print(f"  numpy     best {t_np * per:6.3f} us/pose  (median {m_np * per:6.3f})")
    print(f"  ratio numpy/casecal: {t_np / t_cc:5.1f}x (best)  {m_np / m_cc:5.1f}x (median)")
    # without a C compiler: CasADi's own evaluation, and its instruction list run by numpy
    for backend in ("casadi", "numpy"):
        os.environ["CASECAL_BACKEND"] = backend
        cc.model.kinematics.chain.cache_clear()
        J_b = robot.position_jacobian(q, dh)[0]
        agree = max(agree, float(np.abs(J_b - J_np).max()))
        t_b, m_b = best_time(lambda: robot.position_jacobian(q, dh), max(args.repeat // 3, 3))
        print(
            f"  no compiler, {backend:<6} best {t_b * per:6.3f} us/pose  (median {m_b * per:6.3f})"
            f"  {t_b / t_np:5.2f}x numpy's time (target <= 2x)"
        )
    if agree > 1e-12:
        raise SystemExit("the two implementations disagree: the timing means nothing")


if __name__ == "__main__":
    main()
