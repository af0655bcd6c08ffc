"""Records and helpers shared by the studies and the PDF: figures, tables, plot style."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only: the report never opens a window
import matplotlib.pyplot as plt
import pandas as pd

DEG = math.pi / 180.0
COLORS = {
    "svd": "#d62728",
    "gauss-newton": "#1f77b4",
    "lm": "#2ca02c",
    "ipopt": "#9467bd",
    "seed": "#d62728",
    "uniform": "#1f77b4",
}
METHOD_LABEL = {
    "svd": "one-shot SVD (paper)",
    "gauss-newton": "Gauss-Newton (iterated)",
    "lm": "Levenberg-Marquardt",
    "ipopt": "IPOPT",
}
SCHEDULE_LABEL = {"seed": "paper's schedule", "uniform": "uniform poses"}


@dataclass(frozen=True)
class Figure:
    """A figure file and what a reader should take from it."""

    path: Path
    title: str
    caption: str


@dataclass(frozen=True)
class Table:
    """A table (also written as CSV) for the PDF; `shown` is the part set in the PDF."""

    path: Path
    title: str
    caption: str
    frame: pd.DataFrame
    shown: pd.DataFrame | None = None


@dataclass
class StudyResult:
    """What one study produced."""

    name: str
    title: str
    figures: list[Figure] = field(default_factory=list)
    tables: list[Table] = field(default_factory=list)


def style() -> None:
    """One plot style for every figure: readable at A4 width."""
    plt.rcParams.update(
        {
            "figure.dpi": 110,
            "savefig.dpi": 150,
            "font.size": 9,
            "axes.titlesize": 10,
            "axes.labelsize": 9,
            "legend.fontsize": 8,
            "xtick.labelsize": 8,
            "ytick.labelsize": 8,
            "axes.grid": True,
            "grid.alpha": 0.3,
            "axes.spines.top": False,
            "axes.spines.right": False,
            "legend.handlelength": 3.0,
        }
    )


def pose_axis(ax, counts) -> None:
    """A log x axis labelled at exactly the pose counts of the study."""
    from matplotlib.ticker import FixedLocator, NullLocator

    ax.xaxis.set_major_locator(FixedLocator(list(counts)))
    ax.xaxis.set_minor_locator(NullLocator())
    ax.set_xticklabels([str(c) for c in counts])


def plot_audited(ax, df: pd.DataFrame, x: str, y: str, color, label: str, band: bool = True):
    """Draw Monte Carlo fits on `ax` split by their answer audit (the bool column ``success``).

    Fits that passed: their median per `x` as a solid line with filled markers, labelled
    `label`, and (`band`) the 10–90 % band over them. Fits that failed: each as a hollow
    marker and their median as a dashed line, both thin, labelled "`label`: failed audit",
    so that a failed fit never looks like an estimate. Returns ``{"passed": medians,
    "failed": the failed rows}`` (what was drawn).
    """
    ok = df.success.astype(bool)
    passed, failed = df[ok], df[~ok]
    med = passed.groupby(x)[y].agg(["median", lambda v: v.quantile(0.1), lambda v: v.quantile(0.9)])
    med.columns = ["median", "p10", "p90"]
    if len(passed):
        ax.plot(med.index, med["median"], "-o", ms=3, color=color, label=label)
        if band:
            ax.fill_between(med.index, med.p10, med.p90, color=color, alpha=0.15, lw=0)
    if len(failed):
        fmed = failed.groupby(x)[y].median()
        ax.plot(fmed.index, fmed, "--", lw=0.8, color=color, alpha=0.7)
        ax.plot(
            failed[x],
            failed[y],
            "o",
            ms=4,
            mfc="none",
            mew=0.8,
            color=color,
            alpha=0.8,
            label=f"{label}: failed audit",
        )
    return {"passed": med.reset_index(), "failed": failed}


def save(fig, out: Path, name: str, title: str, caption: str) -> Figure:
    """Write `fig` as PNG into `out` and close it."""
    path = out / f"{name}.png"
    fig.savefig(path, bbox_inches="tight")
    plt.close(fig)
    return Figure(path, title, caption)


def table(
    df: pd.DataFrame,
    out: Path,
    name: str,
    title: str,
    caption: str,
    shown: pd.DataFrame | None = None,
) -> Table:
    """Write `df` as CSV into `out`; `shown` (default `df`) is what the PDF sets."""
    path = out / f"{name}.csv"
    df.to_csv(path, index=False)
    return Table(path, title, caption, df, shown)
