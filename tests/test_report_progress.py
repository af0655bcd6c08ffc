"""The report's progress: labelled on a terminal, plain lines (no carriage returns) elsewhere."""

from __future__ import annotations

import io

from casecal import report
from casecal.report import Progress, run_studies


class _Clock:
    def __init__(self):
        self.now = 0.0

    def __call__(self):
        return self.now


def _fake_studies(monkeypatch, clock):
    """Two studies that map tasks over the runner's progress and take (fake) time."""

    def long_study(out, quick, run):
        for done in range(1, 41):
            clock.now += 5.0  # 200 s for 40 tasks
            run.progress(done, 40)
        return "long"

    def short_study(out, quick, run):
        clock.now += 1.0
        run.progress(1, 1)
        return "short"

    monkeypatch.setattr(report.time, "perf_counter", clock)
    monkeypatch.setattr(report, "style", lambda: None)
    monkeypatch.setitem(report.STUDIES, "long", long_study)
    monkeypatch.setitem(report.STUDIES, "short", short_study)
    monkeypatch.setitem(report.NAMES, "long", "a long study")


class _Runner:
    def __init__(self, progress):
        self.progress = progress


def test_progress_lines_without_a_terminal(monkeypatch, tmp_path):
    clock = _Clock()
    _fake_studies(monkeypatch, clock)
    err = io.StringIO()  # not a terminal
    results = run_studies(["short", "long"], tmp_path, False, _Runner(Progress(stream=err)))
    assert results == ["short", "long"]
    text = err.getvalue()
    assert "\r" not in text
    lines = text.splitlines()
    assert lines[0] == "study 1/2 short: started"
    assert lines[1] == "study 1/2 short: finished in 1.0 s"  # too short for task lines
    assert lines[2] == "study 2/2 a long study: started"
    assert lines[-1] == "study 2/2 a long study: finished in 200.0 s"
    steps = lines[3:-1]
    assert len(steps) == 10, steps  # every 10 % of the tasks
    assert steps[0] == "study 2/2 a long study: 4/40 tasks (10 %), 20 s"
    assert steps[-1].startswith("study 2/2 a long study: 40/40 tasks (100 %)")


def test_progress_says_when_a_map_ends(monkeypatch):
    clock = _Clock()
    monkeypatch.setattr(report.time, "perf_counter", clock)
    err = io.StringIO()
    progress = Progress(stream=err)
    progress.start(1, 1, "x")
    for done in range(1, 49):  # 48 tasks: steps of 5 end at 45; the end is said too
        clock.now += 10.0
        progress(done, 48)
    assert err.getvalue().splitlines()[-1] == "study 1/1 x: 48/48 tasks (100 %), 480 s"


def test_progress_bar_on_a_terminal_is_labelled(monkeypatch, tmp_path):
    clock = _Clock()
    _fake_studies(monkeypatch, clock)
    descs = []

    class FakeBar:
        def __init__(self, total, desc, **kw):
            self.total, self.n = total, 0
            descs.append(desc)

        def update(self, k):
            self.n += k

        def close(self):
            pass

    import tqdm

    monkeypatch.setattr(tqdm, "tqdm", FakeBar)
    err = io.StringIO()
    run_studies(["short", "long"], tmp_path, False, _Runner(Progress(stream=err, tty=True)))
    assert descs == ["study 1/2 short", "study 2/2 a long study"]
    assert err.getvalue() == ""  # the bar (here a fake) writes, no plain lines


def test_study_runner_reports_through_progress():
    assert isinstance(report.study_runner("serial").progress, Progress)
    assert report.study_runner("serial", progress=False).progress is None
