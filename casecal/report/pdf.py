"""Assemble the studies' figures and tables into one PDF (matplotlib's PdfPages, no LaTeX).

Figures and tables flow down A4 portrait pages: a block (heading, content, caption) goes
below the previous one when it fits, else on a new page, so no page is left mostly blank.
"""

from __future__ import annotations

import textwrap
from dataclasses import dataclass, field
from pathlib import Path

import matplotlib.image as mpimg
import matplotlib.pyplot as plt
from matplotlib.backends.backend_pdf import PdfPages

from .common import Figure, StudyResult, Table
from .pdf_table import draw_table, table_height

A4 = (8.27, 11.69)  # inches
MARGIN = 0.05  # of the page height, top and bottom
LEFT = 0.08  # of the page width
GAP = 0.025  # between blocks, of the page height
CAPTION_PT = 9
LINE = CAPTION_PT * 1.4 / 72 / A4[1]  # one caption line, of the page height
HEADING = 0.03


@dataclass
class Layout:
    """Where blocks went: per page, the fraction of its height they fill."""

    filled: list[float] = field(default_factory=list)


class _Flow:
    """A cursor down the current page; opens a new page when a block does not fit."""

    def __init__(self, pdf: PdfPages, layout: Layout):
        self.pdf, self.layout, self.fig, self.y = pdf, layout, None, 0.0

    def place(self, height: float):
        """The figure and the top (fraction) of a free band of `height`."""
        if self.fig is None or self.y - height < MARGIN:
            self.close()
            self.fig, self.y = plt.figure(figsize=A4), 1 - MARGIN
        top = self.y
        self.y -= height + GAP
        return self.fig, top

    @property
    def room(self) -> float:
        """Height left on the current page (0 before the first)."""
        return 0.0 if self.fig is None else self.y - MARGIN

    def close(self) -> None:
        if self.fig is not None:
            self.layout.filled.append((1 - MARGIN - self.y - GAP) / (1 - 2 * MARGIN))
            self.pdf.savefig(self.fig)
            plt.close(self.fig)
            self.fig = None


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


def _wrap(text: str, width: int = 105) -> str:
    return "\n".join(textwrap.wrap(text, width))


def _caption(fig, text: str, top: float) -> None:
    fig.text(LEFT, top, _wrap(text), fontsize=CAPTION_PT, va="top", linespacing=1.4)


def _caption_height(text: str) -> float:
    return (_wrap(text).count("\n") + 1) * LINE


def _figure_block(flow: _Flow, number: int, figure: Figure) -> None:
    img = mpimg.imread(figure.path)
    h, w = img.shape[:2]
    width = 0.84
    height = min(width * h / w * A4[0] / A4[1], 0.55)
    rest = HEADING + 0.01 + _caption_height(figure.caption)
    if height + rest > flow.room >= 0.75 * height + rest:
        height = flow.room - rest  # a little smaller rather than a half-empty page
    width = height * w / h * A4[1] / A4[0]
    fig, top = flow.place(height + rest)
    fig.text(LEFT, top - 0.015, f"Figure {number}. {figure.title}", fontsize=12, weight="bold")
    ax = fig.add_axes([(1 - width) / 2, top - HEADING - height, width, height])
    ax.imshow(img)
    ax.axis("off")
    _caption(fig, figure.caption, top - HEADING - height - 0.01)


def _table_block(flow: _Flow, number: int, tab: Table, max_rows: int = 30) -> None:
    df = (tab.shown if tab.shown is not None else tab.frame).head(max_rows)
    body = table_height(df, A4)
    fig, top = flow.place(HEADING + body + 0.01 + _caption_height(tab.caption))
    fig.text(LEFT, top - 0.015, f"Table {number}. {tab.title}", fontsize=12, weight="bold")
    draw_table(fig, df, top - HEADING, A4)
    _caption(fig, tab.caption, top - HEADING - body - 0.01)


def write_pdf(
    path: Path,
    title: str,
    settings: list[str],
    studies: list[StudyResult],
    table_names: set[str],
    layout: Layout | None = None,
) -> int:
    """Write the report; returns the number of figures in it.

    Only tables whose CSV stem is in `table_names` are set as PDF tables (the trial-level
    CSVs are data, not reading). `layout`, when given, receives how full each page after
    the title page is.
    """
    layout = layout if layout is not None else Layout()
    n_fig = n_tab = 0
    with PdfPages(path) as pdf:
        _title_page(pdf, title, settings)
        flow = _Flow(pdf, layout)
        for study in studies:
            for tab in study.tables:
                if tab.path.stem in table_names:
                    n_tab += 1
                    _table_block(flow, n_tab, tab)
            for figure in study.figures:
                n_fig += 1
                _figure_block(flow, n_fig, figure)
        flow.close()
        info = pdf.infodict()
        info["Title"] = title
        info["Creator"] = "casecal report"
    return n_fig
