"""A fair numpy reference: what a competent engineer would write without casecal.

Standard DH, all joints revolute (the PUMA 560 of the benchmarks). No casecal import.

`frame_position_jacobian` keeps every frame as four (3, N) arrays (the rotation's columns
x, y, z and the origin o), updated joint by joint with elementwise products, never as
(N, 4, 4) matrices, and writes the geometric Jacobian columns straight into a (k, 3, N)
array: ``J.reshape(k, 3 * N)`` is then a contiguous k × 3N matrix whose normal equations
are one matrix product.

`fair_gauss_newton` is Gauss-Newton on the selected columns with the normal equations
JᵀJ and Jᵀr summed over batches of poses (memory O(k² + batch), not O(N k)), column
scaling, a solve of the scaled k × k system, full steps, and the relative-step stop of
the old lstsq reference (`bench_identify.numpy_gauss_newton`) beside the predicted-decrease
stop of casecal's Gauss-Newton. Benchmarks run it on one BLAS thread
(`threadpoolctl.threadpool_limits(1)`).
"""

from __future__ import annotations

import numpy as np

FIELDS = ("theta", "d", "a", "alpha")
BATCH = 16_384  # poses per batch: 22 columns × 3 × 16,384 × 8 B = 8.7 MB, faster than 65,536 here


def column_names(n_joints: int) -> list[str]:
    """Column order of `frame_position_jacobian`: theta1, d1, a1, alpha1, theta2, …"""
    return [f"{f}{i}" for i in range(1, n_joints + 1) for f in FIELDS]


def _cross_into(out, u, v):
    """out[:] = u × v for (3, N) arrays, without (3, N) temporaries beyond one row."""
    np.multiply(u[1], v[2], out=out[0])
    out[0] -= u[2] * v[1]
    np.multiply(u[2], v[0], out=out[1])
    out[1] -= u[0] * v[2]
    np.multiply(u[0], v[1], out=out[2])
    out[2] -= u[1] * v[0]


def frame_position_jacobian(theta, d, a, alpha, q, columns=None, out=None):
    """Tool points and their Jacobian w.r.t. standard-DH parameters, all revolute.

    Parameters
    ----------
    theta, d, a, alpha : array-like, shape (n,)
        DH parameters of the n joints (joint i: Rz(q_i + theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i)).
    q : array-like, shape (N, n)
        Joint angles, rad.
    columns : sequence of int, optional
        Which columns (indices into `column_names(n)`) to compute; default all 4n.
    out : ndarray, shape (len(columns), 3, N), optional
        Where to write the Jacobian.

    Returns
    -------
    p : ndarray, shape (3, N)
        Tool points (origin of the last frame).
    J : ndarray, shape (k, 3, N)
        ∂p/∂param: theta_i: z_{i-1} × (p - o_{i-1}); d_i: z_{i-1}; a_i: x_i;
        alpha_i: x_i × (p - o_i).
    """
    qt = np.ascontiguousarray(np.asarray(q, dtype=float).T)  # (n, N): rows contiguous
    n, N = qt.shape
    cols = list(range(4 * n)) if columns is None else [int(c) for c in columns]
    if out is None:
        out = np.empty((len(cols), 3, N))
    x = np.zeros((3, N))
    y = np.zeros((3, N))
    z = np.zeros((3, N))
    o = np.zeros((3, N))
    x[0], y[1], z[2] = 1.0, 1.0, 1.0
    zs, origins, xs = [z], [o], []  # z_{i-1}, o_{i-1} before joint i; x_i after it
    ct, st = np.empty(N), np.empty(N)
    for i in range(n):
        angle = qt[i] + theta[i]
        np.cos(angle, out=ct)
        np.sin(angle, out=st)
        x_new = x * ct + y * st  # Rz: x' = c x + s y, y' = -s x + c y
        y_rot = y * ct - x * st
        o = o + z * d[i] + x_new * a[i]
        ca, sa = np.cos(alpha[i]), np.sin(alpha[i])
        y = y_rot * ca + z * sa  # Rx: y'' = cα y' + sα z, z'' = -sα y' + cα z
        z = z * ca - y_rot * sa
        x = x_new
        xs.append(x)
        zs.append(z)
        origins.append(o)
    p = o
    diff = np.empty((3, N))
    for j, c in enumerate(cols):
        i, kind = divmod(c, 4)
        if kind == 0:  # theta_i: z_{i-1} x (p - o_{i-1})
            np.subtract(p, origins[i], out=diff)
            _cross_into(out[j], zs[i], diff)
        elif kind == 1:  # d_i: z_{i-1}
            out[j] = zs[i]
        elif kind == 2:  # a_i: x_i
            out[j] = xs[i]
        else:  # alpha_i: x_i x (p - o_i)
            np.subtract(p, origins[i + 1], out=diff)
            _cross_into(out[j], xs[i], diff)
    return p, out


def scaled_solve(As, bs, rcond=1e-12):
    """Solve the scaled normal equations ``As z = bs`` (unit diagonal where not held).

    Cholesky; where it is singular (at a nominal PUMA 560 the wrist's angle columns vanish
    and some lengths duplicate each other, the points lying on the wrist's axes) the
    minimum-norm step, from the eigenvalues above `rcond` times the largest.
    """
    try:
        L = np.linalg.cholesky(As)
        pivots = np.diag(L) ** 2
        if pivots.min() > rcond * pivots.max():
            return np.linalg.solve(L.T, np.linalg.solve(L, bs))
    except np.linalg.LinAlgError:
        pass
    w, V = np.linalg.eigh(As)
    keep = w > rcond * w.max()
    return V[:, keep] @ ((V[:, keep].T @ bs) / w[keep])


def fair_gauss_newton(theta, d, a, alpha, q, y, names, tol=1e-10, max_iter=20, batch=BATCH):
    """Deviations (SI) of the DH parameters `names` by Gauss-Newton; returns (x, iterations).

    Parameters
    ----------
    theta, d, a, alpha : array-like, shape (n,)
        Nominal DH parameters.
    q : array-like, shape (N, n)
        Joint angles, rad.
    y : array-like, shape (N, 3)
        Measured tool points, m.
    names : sequence of str
        Parameters to estimate, e.g. ``["theta2", "a2", …]`` (`column_names`).
    tol : float
        Stop when the scaled step is under `tol` relative to the scaled estimate.
    max_iter : int
    batch : int
        Poses per batch of the normal equations.

    Notes
    -----
    Each iteration: per batch of poses, FK and the selected Jacobian columns
    (`frame_position_jacobian`), then ``A += J Jᵀ`` and ``b += J r`` with J the k × 3B
    matrix. Columns are scaled to unit norm (``s = sqrt(diag A)``), the scaled system
    ``(A / s sᵀ) z = b / s`` solved (Cholesky, `scaled_solve`), and ``x += z / s``. It
    stops when the scaled step is under `tol` relative to the scaled estimate (as the old
    lstsq reference did), or when the cost decrease the step promised is under `tol` times
    the cost plus a rounding floor (as casecal's Gauss-Newton does: the normal equations
    square the condition number, so on noise-free data the step alone would wander at
    their rounding floor, ~1e-12 relative, above `tol`).
    """
    theta, d, a, alpha = (np.asarray(v, dtype=float) for v in (theta, d, a, alpha))
    q = np.asarray(q, dtype=float)
    n_poses, n = q.shape
    order = column_names(n)
    idx = [order.index(str(name)) for name in names]
    k = len(idx)
    p0 = np.stack([theta, d, a, alpha], axis=1).ravel()  # column_names layout
    yt = np.ascontiguousarray(np.asarray(y, dtype=float).T)  # (3, N)
    batch = max(1, min(int(batch), n_poses))
    buf = np.empty((k, 3, batch))
    x = np.zeros(k)
    # residuals of a few ε of the largest coordinate are rounding: nothing left to gain
    floor = 0.5 * yt.size * (4 * np.finfo(float).eps * np.abs(yt).max()) ** 2
    for it in range(1, max_iter + 1):
        par = p0.copy()
        par[idx] += x
        th, dd, aa, al = par[0::4], par[1::4], par[2::4], par[3::4]
        A = np.zeros((k, k))
        b = np.zeros(k)
        cost = 0.0
        for s in range(0, n_poses, batch):
            e = min(s + batch, n_poses)
            m = e - s
            J = buf[:, :, :m] if m == batch else np.empty((k, 3, m))
            f, J = frame_position_jacobian(th, dd, aa, al, q[s:e], idx, out=J)
            r = yt[:, s:e] - f
            J2 = J.reshape(k, 3 * m)
            A += J2 @ J2.T
            b += J2 @ r.ravel()
            cost += 0.5 * float(np.dot(r.ravel(), r.ravel()))
        norms = np.sqrt(np.diag(A))
        norms[norms <= 1e-12 * norms.max()] = np.inf  # a column that is zero here: held
        bs = b / norms
        z = scaled_solve(A / np.outer(norms, norms), bs)
        x = x + z / norms
        norms[np.isinf(norms)] = 0.0
        predicted = 0.5 * float(z @ bs)  # the cost decrease this step promises
        if np.linalg.norm(z) <= tol * (np.linalg.norm(x * norms) + tol):
            return x, it
        if predicted <= tol * cost + floor:
            return x, it
    return x, max_iter
