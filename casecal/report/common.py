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
