"""The report's PDF layout and plots, without running a study: titles within the margins,
pages filled, failed fits drawn apart from those that passed."""

from __future__ import annotations

import re

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from casecal.report.common import Figure, StudyResult, Table, plot_audited
from casecal.report.pdf import A4, Layout, title_lines, write_pdf
from casecal.report.pdf_table import WIDTH, _text_width

LONG = "Table 3. Six-axis arms: what positions can identify, with and without Hayati's β"


def test_titles_fit_between_the_margins():
    room = WIDTH * A4[0] * 72
    assert _text_width(LONG, 12, True) > room  # the title that ran past the margin
    lines = title_lines(LONG)
    assert len(lines) == 2 and " ".join(lines) == LONG
    assert all(_text_width(line, 12, True) <= room for line in lines)
    assert title_lines("Figure 2. Planar arms") == ["Figure 2. Planar arms"]


def _png(path, height):
    fig = plt.figure(figsize=(6, height))
    fig.add_subplot().plot([0, 1], [0, 1])
    fig.savefig(path)
    plt.close(fig)
    return path


def test_pages_are_filled(tmp_path):
    """A tall figure that does not fit after a short one waits while the next fills the page."""
    caption = "A caption of a few words. " * 8
    figures = [
        Figure(_png(tmp_path / "a.png", 2.5), "short " + LONG, caption),
        Figure(_png(tmp_path / "b.png", 5.5), "tall", caption),
        Figure(_png(tmp_path / "c.png", 2.5), "short again", caption),
        Figure(_png(tmp_path / "d.png", 5.5), "tall again", caption),
    ]
    frame = pd.DataFrame({"robot": ["kr15_2", "rx90b"], "rank": [24, 25]})
    tab = Table(tmp_path / "t.csv", LONG, caption, frame)
    study = StudyResult("s", "study", figures=figures, tables=[tab])
    layout = Layout()
    n = write_pdf(tmp_path / "r.pdf", "t", ["x"], [study], {"t"}, layout)
    assert n == 4
    pdf = (tmp_path / "r.pdf").read_bytes()
    assert len(re.findall(rb"/Type\s*/Page[^s]", pdf)) == 1 + len(layout.filled)
    assert min(layout.filled[:-1]) > 0.4, layout.filled
    # the table and the first short figure leave too little room for the tall one, so the
    # second short figure fills the first page (in order it would be 54 % full)
    assert layout.filled[0] > 0.75, layout.filled


def test_failed_fits_are_drawn_apart():
    df = pd.DataFrame(
        {
            "n_poses": [30, 30, 30, 100, 100, 100],
            "rms_holdout_mm": [0.05, 0.06, 0.5, 0.04, 0.05, 0.45],
            "success": [True, True, False, True, True, False],
        }
    )
    fig, ax = plt.subplots()
    drawn = plot_audited(ax, df, "n_poses", "rms_holdout_mm", "C0", "standard DH")
    np.testing.assert_allclose(drawn["passed"]["median"], [0.055, 0.045])
    assert list(drawn["failed"].rms_holdout_mm) == [0.5, 0.45]
    labels = ax.get_legend_handles_labels()[1]
    assert labels == ["standard DH", "standard DH: failed audit"]
    hollow = next(h for h in ax.lines if h.get_label().endswith("failed audit"))
    assert hollow.get_markerfacecolor() == "none"
    np.testing.assert_allclose(hollow.get_ydata(), [0.5, 0.45])
    # every fit failed: nothing is drawn as an estimate
    ax2 = fig.add_subplot(2, 1, 2)
    drawn = plot_audited(ax2, df.assign(success=False), "n_poses", "rms_holdout_mm", "C1", "DH")
    assert drawn["passed"].empty
    assert ax2.get_legend_handles_labels()[1] == ["DH: failed audit"]
    plt.close(fig)


def test_a_figure_shrunk_to_fit_stays_on_the_page(tmp_path):
    """Sized to the room left, a figure is not pushed to a new page by rounding."""
    caption = "A caption of a few words. " * 8
    figures = [
        Figure(_png(tmp_path / "a.png", 3.5), "short", caption),
        Figure(_png(tmp_path / "b.png", 6.0), "tall, shrunk", caption),
    ]
    layout = Layout()
    write_pdf(tmp_path / "r.pdf", "t", ["x"], [StudyResult("s", "s", figures)], set(), layout)
    assert len(layout.filled) == 1 and layout.filled[0] > 0.99, layout.filled
