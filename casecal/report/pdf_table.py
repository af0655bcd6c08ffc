"""A table set as text with three rules (top, below the header, bottom), sized to its content.

Text columns read from the left, numbers align on the right; long text wraps in its cell;
the font shrinks (down to 5.5 pt) until the table fits the page width.
"""

from __future__ import annotations

import textwrap
from dataclasses import dataclass
from functools import lru_cache

import pandas as pd
from matplotlib.backends.backend_agg import RendererAgg
from matplotlib.font_manager import FontProperties
from matplotlib.lines import Line2D

LEFT = 0.08  # of the page width, as the captions
WIDTH = 0.84  # of the page width
PAD = 4.0  # pt, between columns
LEADING = 1.3  # line height per font size
TEXT_WRAPS = (90, 70, 55, 40, 30)  # characters of a text cell per line, tried in turn
HEADER_WRAP = 14


@dataclass(frozen=True)
class _Set:
    """A table's cells broken into lines, and the sizes they take at font size `pt`."""

    header: list[list[str]]
    rows: list[list[list[str]]]
    numeric: list[bool]
    widths: list[float]  # pt, per column, padding included
    pt: float

    def row_height(self, cells) -> float:
        return max(len(c) for c in cells) * self.pt * LEADING + PAD

    @property
    def height(self) -> float:
        """pt, rules included."""
        return self.row_height(self.header) + sum(self.row_height(r) for r in self.rows) + PAD


def _cell(v) -> str:
    if isinstance(v, float):
        if v == 0 or 1e-3 <= abs(v) < 1e4:
            return f"{v:.6f}"
        return f"{v:.3e}"
    return str(v)


@lru_cache(maxsize=4096)
def _text_width(text: str, pt: float, bold: bool) -> float:
    """Width of `text` in points."""
    renderer = _renderer()
    font = FontProperties(size=pt, weight="bold" if bold else "normal")
    return renderer.get_text_width_height_descent(text, font, ismath=False)[0]


@lru_cache(maxsize=1)
def _renderer() -> RendererAgg:
    return RendererAgg(10, 10, 72)  # 72 dpi: pixels are points


def _set(df: pd.DataFrame, page: tuple[float, float]) -> _Set:
    numeric = [pd.api.types.is_numeric_dtype(df[c]) for c in df.columns]
    header = [textwrap.wrap(str(c), HEADER_WRAP) or [""] for c in df.columns]
    room = WIDTH * page[0] * 72
    # the largest font first, and at each font the longest lines that fit
    for pt in (8.0, 7.5, 7.0, 6.5, 6.0, 5.5):
        for wrap in TEXT_WRAPS:
            rows = [
                [
                    [_cell(v)] if num else textwrap.wrap(_cell(v), wrap) or [""]
                    for v, num in zip(row, numeric, strict=True)
                ]
                for row in df.itertuples(index=False)
            ]
            widths = [
                max(
                    max(_text_width(line, pt, True) for line in header[j]),
                    *(max(_text_width(line, pt, False) for line in r[j]) for r in rows),
                )
                + 2 * PAD
                for j in range(len(header))
            ]
            if sum(widths) <= room:
                return _Set(header, rows, numeric, widths, pt)
    return _Set(header, rows, numeric, widths, pt)  # the smallest: as good as it gets


def table_height(df: pd.DataFrame, page: tuple[float, float]) -> float:
    """Height of `df` set as a table, as a fraction of the page height."""
    return _set(df, page).height / (page[1] * 72)


def draw_table(fig, df: pd.DataFrame, top: float, page: tuple[float, float]) -> None:
    """Set `df` on `fig` (a page of `page` inches) from `top` (fraction of its height) down."""
    s = _set(df, page)
    w_pt, h_pt = page[0] * 72, page[1] * 72
    right = LEFT + sum(s.widths) / w_pt

    def rule(y: float, lw: float) -> None:
        fig.add_artist(Line2D([LEFT, right], [y, y], lw=lw, color="k"))

    def line_of(cells, y: float, bold: bool) -> float:
        x = LEFT
        for cell, width, num in zip(cells, s.widths, s.numeric, strict=True):
            fig.text(
                x + (width - PAD if num else PAD) / w_pt,
                y - PAD / 2 / h_pt,
                "\n".join(cell),
                fontsize=s.pt,
                weight="bold" if bold else "normal",
                ha="right" if num else "left",
                va="top",
                linespacing=LEADING,
            )
            x += width / w_pt
        return y - s.row_height(cells) / h_pt

    rule(top, 1.0)
    y = line_of(s.header, top, bold=True)
    rule(y, 0.6)
    for cells in s.rows:
        y = line_of(cells, y, bold=False)
    rule(y - PAD / 2 / h_pt, 1.0)
