"""Assemble the studies' figures and tables into one PDF (matplotlib's PdfPages, no LaTeX)."""

from __future__ import annotations

import textwrap
from pathlib import Path

import matplotlib.image as mpimg
import matplotlib.pyplot as plt
from matplotlib.backends.backend_pdf import PdfPages

from .common import Figure, StudyResult, Table

A4 = (8.27, 11.69)


def _title_page(pdf: PdfPages, title: str, lines: list[str]) -> None:
    fig = plt.figure(figsize=A4)
    fig.text(0.5, 0.9, title, ha="center", fontsize=20, weight="bold")
    fig.text(
        0.5, 0.86, "Kinematic calibration of serial robot arms: studies", ha="center", fontsize=12
    )
    y = 0.78
    for line in lines:
        for part in textwrap.wrap(line, 95) or [""]:
            fig.text(
                0.08, y, part, fontsize=9, family="monospace" if line.startswith("  ") else None
            )
            y -= 0.021
    pdf.savefig(fig)
    plt.close(fig)


def _caption(fig, text: str, y: float, width: int = 105) -> None:
    wrapped = "\n".join(textwrap.wrap(text, width))
    fig.text(0.08, y, wrapped, fontsize=9, va="top", linespacing=1.4)


def _figure_page(pdf: PdfPages, number: int, figure: Figure) -> None:
    fig = plt.figure(figsize=A4)
    img = mpimg.imread(figure.path)
    h, w = img.shape[:2]
    width = 0.84
    height = min(width * h / w * A4[0] / A4[1], 0.55)
    width = height * w / h * A4[1] / A4[0]
    ax = fig.add_axes([(1 - width) / 2, 0.88 - height, width, height])
    ax.imshow(img)
    ax.axis("off")
    fig.text(0.08, 0.93, f"Figure {number}. {figure.title}", fontsize=12, weight="bold")
    _caption(fig, figure.caption, 0.86 - height)
    pdf.savefig(fig)
    plt.close(fig)


def _table_page(pdf: PdfPages, number: int, tab: Table, max_rows: int = 30) -> None:
    df = (tab.shown if tab.shown is not None else tab.frame).head(max_rows)
    fig = plt.figure(figsize=(A4[1], A4[0]))  # landscape: tables are wide
    fig.text(0.05, 0.93, f"Table {number}. {tab.title}", fontsize=12, weight="bold")
    ax = fig.add_axes([0.03, 0.32, 0.94, 0.56])
    ax.axis("off")
    cells = [[_cell(v) for v in row] for row in df.itertuples(index=False)]
    t = ax.table(
        cellText=cells,
        colLabels=[str(c) for c in df.columns],
        loc="upper center",
        cellLoc="right",
        colLoc="center",
    )
    t.auto_set_font_size(False)
    t.set_fontsize(7.5)
    t.auto_set_column_width(list(range(len(df.columns))))
    t.scale(1.0, 1.5)
    for (row, col), cell in t.get_celld().items():
        if row > 0 and isinstance(df.iloc[row - 1, col], str):
            cell._loc = "left"  # text reads from the left; numbers align on the right
    _caption(fig, tab.caption, 0.28, width=150)
    pdf.savefig(fig)
    plt.close(fig)


def _cell(v) -> str:
    if isinstance(v, float):
        if v == 0 or 1e-3 <= abs(v) < 1e4:
            return f"{v:.6f}"
        return f"{v:.3e}"
    return str(v)


def write_pdf(
    path: Path, title: str, settings: list[str], studies: list[StudyResult], table_names: set[str]
) -> int:
    """Write the report; returns the number of figures in it.

    Only tables whose CSV stem is in `table_names` are set as PDF tables (the trial-level
    CSVs are data, not reading).
    """
    n_fig = n_tab = 0
    with PdfPages(path) as pdf:
        _title_page(pdf, title, settings)
        for study in studies:
            for tab in study.tables:
                if tab.path.stem in table_names:
                    n_tab += 1
                    _table_page(pdf, n_tab, tab)
            for figure in study.figures:
                n_fig += 1
                _figure_page(pdf, n_fig, figure)
        info = pdf.infodict()
        info["Title"] = title
        info["Creator"] = "casecal report"
    return n_fig
