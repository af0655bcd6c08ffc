"""Residual plots of one calibration: by pose, by joint value, before and after.

A leaf like the rest of the report (matplotlib, files only): `residual_figure` draws,
`plot_residuals` writes a PNG. The poses that stand out (`Calibration.outliers`) are
marked in every panel, so a reader sees at once whether they are a few gross readings or
a region of the workspace.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .common import plt

BEFORE, AFTER, OUTLIER = "#bbbbbb", "#1f77b4", "#d62728"


def pose_errors(cal) -> tuple[np.ndarray, np.ndarray]:
    """Largest point error of each pose before and after calibration, mm, shape (N,)."""
    table = cal.residual_table()
    by_pose = table.groupby("pose")
    return (
        by_pose["error_before_mm"].max().to_numpy(),
        by_pose["error_after_mm"].max().to_numpy(),
    )


def residual_figure(cal, q: np.ndarray, joint_types: str | None = None):
    """A matplotlib Figure: error by pose, the distribution before and after, and the
    error after calibration against each joint's value.

    Parameters
    ----------
    cal : Calibration
    q : ndarray, shape (N, dof)
        The joint values the calibration was fitted to, rad (R) or m (P).
    joint_types : str, optional
        ``"R"``/``"P"`` per joint (default: the robot's), for the axes' units (deg, mm).
    """
    before, after = pose_errors(cal)
    q = np.asarray(q, dtype=float)
    if q.shape[0] != before.size:
        raise ValueError(f"q has {q.shape[0]} poses; the calibration has {before.size}")
    # controller joints only: a file's per-pose inputs (payload_kg) follow them in q
    types = joint_types or cal.nominal.controller_types
    dof = len(types)
    q = q[:, :dof]
    out = np.asarray(cal.outliers, dtype=int)
    columns = max(min(dof, 4), 2)
    rows = 1 + -(-dof // columns)
    fig = plt.figure(figsize=(3.0 * columns, 2.6 * rows), layout="constrained")
    grid = fig.add_gridspec(rows, columns)
    ax = fig.add_subplot(grid[0, : columns - 1])
    poses = np.arange(before.size)
    ax.plot(poses, before, ".", color=BEFORE, ms=3, label="before")
    ax.plot(poses, after, ".", color=AFTER, ms=3, label="after")
    ax.plot(out, after[out], "x", color=OUTLIER, ms=6, label="stands out", gid="outliers")
    # a few gross readings would flatten the rest against zero: a log axis shows both
    yscale = "log" if after.max(initial=0.0) > 10 * max(np.median(after), 1e-12) else "linear"
    ax.set(xlabel="pose", ylabel="error, mm", title="error of each pose", yscale=yscale)
    ax.legend(loc="upper right", fontsize="small")
    hist = fig.add_subplot(grid[0, columns - 1])
    edges = np.linspace(0.0, max(before.max(initial=0.0), after.max(initial=0.0)) or 1.0, 31)
    hist.hist(before, bins=edges, color=BEFORE, label="before")
    hist.hist(after, bins=edges, color=AFTER, alpha=0.8, label="after")
    hist.set(xlabel="error, mm", ylabel="poses", title="distribution")
    hist.legend(loc="upper right", fontsize="small")
    for j in range(dof):
        sub = fig.add_subplot(grid[1 + j // columns, j % columns])
        scale, unit = (1e3, "mm") if types[j] == "P" else (180.0 / np.pi, "deg")
        sub.plot(q[:, j] * scale, after, ".", color=AFTER, ms=3)
        sub.plot(q[out, j] * scale, after[out], "x", color=OUTLIER, ms=6)
        sub.set(xlabel=f"joint {j + 1}, {unit}", ylabel="error after, mm", yscale=yscale)
    fig.suptitle(
        f"{cal.n_poses} poses: RMS {cal.rms_before * 1e3:.3g} mm before, "
        f"{cal.rms * 1e3:.3g} mm after; {len(out)} stand{'s' if len(out) == 1 else ''} out"
    )
    return fig


def plot_residuals(cal, q: np.ndarray, path) -> Path:
    """Write `residual_figure` to `path` (PNG, 150 dpi) and return it."""
    path = Path(path)
    fig = residual_figure(cal, q)
    try:
        fig.savefig(path, dpi=150)
    finally:
        plt.close(fig)
    return path
