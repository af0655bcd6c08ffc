"""What a command will write is checked before it works (issue 20, adversarial retest).

An output that is one of the command's inputs, or another output's file, is refused before
anything runs; a report refuses a user's file of one of its names, a folder the user is
in (also through a link), and a scheduler nothing answers at before its first study; and
a report that fails leaves no folder it made, saying where a full disk stopped it.
"""

from __future__ import annotations

import errno

import pytest

import casecal.report as report
from casecal.cli import main

REAL_RUNNER = report.study_runner  # before the fake_report fixture replaces it


@pytest.fixture
def measured(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["simulate", "rr", "--poses", "12", "-o", "m.csv"]) == 0
    capsys.readouterr()
    return tmp_path / "m.csv"


@pytest.mark.parametrize(
    "argv, reason",
    [
        (["identify", "rr", "m.csv", "--noise", "0.01mm", "--deviations-out", "m.csv"], "input"),
        (["identify", "rr", "m.csv", "-o", "./m.csv"], "input"),
        (["identify", "rr", "m.csv", "--deviations-out", "link.csv"], "input"),
        (["identify", "rr", "m.csv", "-o", "same.toml", "--deviations-out", "same.toml"], "both"),
        (["compensate", "rr", "m.csv", "--nominal", "rr", "-o", "m.csv"], "input"),
    ],
)
def test_an_output_that_is_an_input_or_another_output_is_refused(measured, capsys, argv, reason):
    (measured.parent / "link.csv").symlink_to(measured)
    before = measured.read_bytes()
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("casecal: error: ") and err.count("\n") == 1
    assert ("also the file read as" in err) if reason == "input" else ("both name" in err)
    assert measured.read_bytes() == before
    assert sorted(p.name for p in measured.parent.iterdir()) == ["link.csv", "m.csv"]


def test_writing_over_an_earlier_output_is_still_fine(measured, capsys):
    assert main(["simulate", "rr", "--poses", "3", "-o", "m.csv"]) == 0


def test_a_users_file_of_a_report_name_is_refused_before_any_study(tmp_path, fake_report, capsys):
    assert "table1.csv" in report.OUTPUTS
    out = tmp_path / "rep"
    out.mkdir()
    (out / "table1.csv").write_text("mine")
    fake_report.fail = AssertionError("a study ran")
    assert main(["report", "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "table1.csv" in err and "was not written by casecal" in err
    assert (out / "table1.csv").read_text() == "mine"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rep"]


def test_the_folder_you_are_in_is_refused_through_a_link(
    tmp_path, fake_report, capsys, monkeypatch
):
    (tmp_path / "real" / "work").mkdir(parents=True)
    (tmp_path / "alias").symlink_to(tmp_path / "real")
    monkeypatch.chdir(tmp_path / "real" / "work")
    fake_report.fail = AssertionError("a study ran")
    for target in (tmp_path / "alias" / "work", tmp_path / "alias"):
        assert main(["report", "-o", str(target)]) == 2
        assert "folder you are in" in capsys.readouterr().err
    assert sorted(p.name for p in (tmp_path / "real").iterdir()) == ["work"]
    assert list((tmp_path / "real" / "work").iterdir()) == []


@pytest.mark.parametrize(
    "failure",
    [OSError(errno.ENOSPC, "No space left on device"), KeyboardInterrupt()],
    ids=["full disk", "Ctrl-C"],
)
def test_a_failed_first_report_leaves_no_folder(tmp_path, fake_report, capsys, failure):
    out = tmp_path / "rep"
    fake_report.fail = failure
    code = main(["report", "-o", str(out)])
    err = capsys.readouterr().err
    assert code == (130 if isinstance(failure, KeyboardInterrupt) else 2), err
    assert err.count("\n") == 1
    if isinstance(failure, OSError):
        assert str(out) in err and "No space left on device" in err and "nothing was written" in err
    assert list(tmp_path.iterdir()) == []


def test_a_scheduler_nothing_answers_at_is_said_before_any_study(
    tmp_path, fake_report, capsys, monkeypatch
):
    pytest.importorskip("dask.distributed")
    from casecal.studies.executor import Executor

    check = Executor.check_reachable
    monkeypatch.setattr(Executor, "check_reachable", lambda self: check(self, timeout=2.0))
    monkeypatch.setattr(report, "study_runner", REAL_RUNNER)
    fake_report.fail = AssertionError("a study ran")
    out = tmp_path / "rep"
    assert main(["report", "--scheduler", "tcp://127.0.0.1:1", "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "no dask scheduler answers at 'tcp://127.0.0.1:1'" in err and "--scheduler" in err
    assert list(tmp_path.iterdir()) == []
