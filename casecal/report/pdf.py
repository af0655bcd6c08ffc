"""Assemble the studies' figures and tables into one PDF (matplotlib's PdfPages, no LaTeX).

Figures and tables flow down A4 portrait pages: a block (heading, content, caption) goes
below the previous one when it fits, else on a new page, so no page is left mostly blank.
A figure shrinks (to 65 % at most) rather than leave a page half empty, and where the next
block does not fit, one of the two after it that does fills the page first; blocks are
numbered in the order they appear. Titles wrap at the measured width between the margins.
"""

from __future__ import annotations

import textwrap
from dataclasses import dataclass, field
from pathlib import Path

import matplotlib.image as mpimg
import matplotlib.pyplot as plt
from matplotlib.backends.backend_pdf import PdfPages

from .common import Figure, StudyResult, Table
from .pdf_table import WIDTH, _text_width, draw_table, table_height

A4 = (8.27, 11.69)  # inches
MARGIN = 0.05  # of the page height, top and bottom
LEFT = 0.08  # of the page width
GAP = 0.025  # between blocks, of the page height
CAPTION_PT = 9
LINE = CAPTION_PT * 1.4 / 72 / A4[1]  # one caption line, of the page height
HEADING = 0.03  # one line of a block's title
TITLE_PT = 12
TITLE_LINE = TITLE_PT * 1.25 / 72 / A4[1]  # each further line of a title
SHRINK = 0.65  # how small a figure may get to fill a page, of its natural height
LOOKAHEAD = 2  # how many blocks ahead one may be taken to fill a page
MAX_ROWS = 30  # of a table set in the PDF


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
        if self.fig is None or self.y - height < MARGIN - 1e-9:  # rounding: a block sized to fit
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


def title_lines(text: str, pt: float = TITLE_PT) -> list[str]:
    """`text` in bold at `pt`, broken at spaces into lines that each fit between the margins."""
    room = WIDTH * A4[0] * 72  # points
    lines: list[str] = []
    for word in text.split(" "):
        trial = f"{lines[-1]} {word}" if lines else word
        if lines and _text_width(trial, pt, True) > room:
            lines.append(word)
        else:
            lines[-1:] = [trial]
    return lines


def _heading_height(text: str) -> float:
    return HEADING + (len(title_lines(text)) - 1) * TITLE_LINE


def _heading(fig, text: str, top: float) -> None:
    fig.text(
        LEFT,
        top - 0.004,
        "\n".join(title_lines(text)),
        fontsize=TITLE_PT,
        weight="bold",
        va="top",
        linespacing=1.25,
    )


class _Block:
    """A figure or a table with its heading and caption, and the band of page it needs."""

    def __init__(self, kind: str, item: Figure | Table):
        self.kind, self.item = kind, item
        if kind == "Figure":
            h, w = mpimg.imread(item.path).shape[:2]
            self.aspect = h / w  # of the image
            self.image = min(0.84 * self.aspect * A4[0] / A4[1], 0.55)
        else:
            df = item.shown if item.shown is not None else item.frame
            self.frame = df.head(MAX_ROWS)
            self.image = table_height(self.frame, A4)
        # sized for a two-digit number: the title may wrap one word earlier than with one
        self.rest = _heading_height(self.heading(99)) + 0.01 + _caption_height(item.caption)

    def heading(self, number: int) -> str:
        return f"{self.kind} {number}. {self.item.title}"

    @property
    def height(self) -> float:
        return self.image + self.rest

    @property
    def smallest(self) -> float:
        """A figure may shrink a little rather than leave a half-empty page; a table not."""
        return (SHRINK * self.image if self.kind == "Figure" else self.image) + self.rest

    def fits(self, room: float) -> bool:
        return self.smallest <= room

    def draw(self, flow: _Flow, number: int) -> None:
        image = self.image
        if self.kind == "Figure" and self.height > flow.room >= self.smallest:
            image = flow.room - self.rest
        fig, top = flow.place(image + self.rest)
        _heading(fig, self.heading(number), top)
        top -= _heading_height(self.heading(number))
        if self.kind == "Figure":
            width = image / self.aspect * A4[1] / A4[0]
            ax = fig.add_axes([(1 - width) / 2, top - image, width, image])
            ax.imshow(mpimg.imread(self.item.path))
            ax.axis("off")
        else:
            draw_table(fig, self.frame, top, A4)
        _caption(fig, self.item.caption, top - image - 0.01)


def _next_block(blocks: list[_Block], flow: _Flow) -> _Block:
    """The next block in order, unless it does not fit the current page while one of the
    next `LOOKAHEAD` does: that one fills the page first (a half-empty page otherwise)."""
    room = flow.room
    if flow.fig is not None and not blocks[0].fits(room):
        for j in range(1, min(len(blocks), 1 + LOOKAHEAD)):
            if blocks[j].fits(room):
                return blocks.pop(j)
    return blocks.pop(0)


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
    blocks = []
    for study in studies:
        blocks += [_Block("Table", t) for t in study.tables if t.path.stem in table_names]
        blocks += [_Block("Figure", f) for f in study.figures]
    numbers = {"Figure": 0, "Table": 0}
    with PdfPages(path) as pdf:
        _title_page(pdf, title, settings)
        flow = _Flow(pdf, layout)
        while blocks:
            block = _next_block(blocks, flow)
            numbers[block.kind] += 1  # numbered in the order they appear
            block.draw(flow, numbers[block.kind])
        flow.close()
        info = pdf.infodict()
        info["Title"] = title
        info["Creator"] = "casecal report"
    return numbers["Figure"]
