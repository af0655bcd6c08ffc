"""The report: every study runs, writes its files, and the numbers in them make sense."""

from __future__ import annotations

import re

import numpy as np
import pandas as pd

from casecal.report import OUTPUTS, PDF_TABLES, run_studies, study_runner
from casecal.report.pdf import Layout, write_pdf
from casecal.report.studies_paper import PAPER_TABLE1


def test_quick_report(tmp_path):
    results = run_studies(
        ["table1", "planar_arms", "scara", "pose_count", "noise", "six_axis"],
        tmp_path,
        quick=True,
        run=study_runner("serial", progress=False),
    )
    # what the studies wrote is what the report refuses up front where a user's file has it
    assert {p.name for p in tmp_path.iterdir()} <= OUTPUTS
    layout = Layout()
    n = write_pdf(tmp_path / "r.pdf", "test", ["settings"], results, PDF_TABLES, layout)
    assert n >= 8
    pdf = (tmp_path / "r.pdf").read_bytes()
    pages = len(re.findall(rb"/Type\s*/Page[^s]", pdf))
    assert pages == 1 + len(layout.filled)  # the title page, then the flow
    # figures and tables flow down the pages: none but the last is left mostly blank
    assert min(layout.filled[:-1]) > 0.4, layout.filled
    for study in results:
        for fig in study.figures:
            assert fig.path.is_file() and fig.path.stat().st_size > 10_000
            assert "nan" not in fig.caption.lower(), fig.caption
        for tab in study.tables:
            assert tab.path.is_file()

    # Table 1: one shot at least as good as the paper, iterated exact, all nine rows
    t1 = pd.read_csv(tmp_path / "table1.csv")
    assert len(t1) == len(PAPER_TABLE1)
    assert t1["one-shot 100 error %"].abs().max() < 0.1813
    assert t1["iterated 100 error %"].abs().max() < 1e-6
    np.testing.assert_allclose(t1["synthetic"], [v[0] for v in PAPER_TABLE1.values()])
    # every error column in one convention, (identified - synthetic) / |synthetic|: where the
    # paper's printed values differ, its error has their sign (the paper's Δθ1 row is
    # inconsistent and said so in the caption)
    differ = (t1["paper identified"] != t1["synthetic"]) & (t1.deviation != "Δθ1")
    shown = t1[differ]
    assert len(shown) >= 5
    assert (
        np.sign(shown["paper error %"]) == np.sign(shown["paper identified"] - shown["synthetic"])
    ).all()
    assert (
        t1.deviation.str.startswith("Δθ").sum() == 4
        and not t1.deviation.str.contains("theta").any()
    )
    caption = next(t.caption for s in results for t in s.tables if t.path.stem == "table1")
    assert "Δθ1 row is inconsistent" in caption

    # the SCARA table's reason does not repeat the group's names or combinations
    blind = pd.read_csv(tmp_path / "scara_blind_spots.csv")
    for _, row in blind.iterrows():
        for name in row["parameters"].split(", "):
            assert name not in row["why"]

    # pose count: every trial is in the table; a fit that passed its audit rarely ends
    # worse than the uncalibrated robot (the audit predicts, it cannot know), and the
    # figure rings and counts those that do; with uniform poses the iterated error falls
    pc = pd.read_csv(tmp_path / "pose_count_trials.csv")
    assert len(pc) == 2 * 4 * 2 * 2 * 4  # robots × counts × schedules × methods × trials
    worse = pc.success & (pc.rms_holdout_mm > pc.rms_holdout_before_mm)
    assert worse.sum() <= 0.05 * pc.success.sum()
    caption = next(
        f.caption for s in results for f in s.figures if f.path.stem == "pose_count_error"
    )
    assert "uncalibrated" in caption and "failed their audit" in caption
    assert f"worse than uncalibrated: {int(worse.sum())}." in caption
    uni = pc[(pc.schedule == "uniform") & (pc.method == "gauss-newton")]
    for _, g in uni.groupby("robot"):
        med = g.groupby("n_poses")["rms_holdout_mm"].median()
        assert med.is_monotonic_decreasing, med

    # six-axis: Hayati's beta beats standard DH at the largest pose count, on both robots
    six = pd.read_csv(tmp_path / "six_axis_trials.csv")
    big = (
        six[six.n_poses == six.n_poses.max()].groupby(["robot", "model"])["rms_holdout_mm"].median()
    )
    for robot in ("kr15_2", "rx90b"):
        with_beta = big[robot][big[robot].index.str.contains("β")].iloc[0]
        standard = big[robot][big[robot].index.str.startswith("standard")].iloc[0]
        assert with_beta < 0.5 * standard


def test_compliance_study(tmp_path):
    (result,) = run_studies(
        ["compliance"], tmp_path, quick=True, run=study_runner("serial", progress=False)
    )
    df = pd.read_csv(tmp_path / "compliance_trials.csv")
    rigid, known = df[df.model == "rigid"], df[df.model == "compliance, masses known"]
    assert not rigid.success.any() and rigid.rms_holdout_mm.min() > 1.0  # mm: it cannot bend
    assert known.success.all() and known.rms_holdout_mm.max() < 0.05
    caption = result.figures[0].caption
    assert "fail their answer audit" in caption and "nan" not in caption.lower()
