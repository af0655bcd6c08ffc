"""Reading measurement CSV files: encodings, comment lines, exact numbers, memory, and a
gross value in one row named first (issue 20, findings 12, 14 and 16)."""

from __future__ import annotations

import os
import re
import subprocess
import sys

import numpy as np
import pytest

import casecal as cc
from casecal.cli import main
from casecal.data import table
from casecal.errors import CalibrationError


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    """60 simulated poses of the puma560, with 0.01 mm noise: the file's text."""
    path = tmp_path_factory.mktemp("sim") / "sim.csv"
    argv = ["simulate", "puma560", "--poses", "60", "--schedule", "uniform"]
    assert main([*argv, "--noise", "0.01mm", "-o", str(path)]) == 0
    return path.read_text()


def one_error_line(capsys) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("casecal: error: "), err
    return err


def test_a_gross_value_in_one_row_is_named_first(simulated, tmp_path, capsys):
    """Finding 14: the message led with 'the fit stopped before the minimum'; the cause was
    note [5] or [6]."""
    lines = simulated.splitlines()
    header = lines[0].split(",")
    row = lines[8].split(",")  # file row 9: the header is row 1
    k = header.index("x_mm")
    row[k] = repr(float(row[k]) + 500.0)
    lines[8] = ",".join(row)
    path = tmp_path / "gross.csv"
    path.write_text("\n".join(lines) + "\n")
    assert main(["identify", "puma560", str(path)]) == 2
    captured = capsys.readouterr()
    err = captured.err
    assert err.count("\n") == 1 and err.startswith("casecal: error: "), err
    # the cause leads the error line: the row, and what to do, before the audit's findings
    cause = err.find("file row 9")
    assert 0 <= cause < err.find("audit") and "--loss huber" in err[: err.find("audit")], err
    message = next(x for x in captured.out.splitlines() if x.startswith("Message:"))
    assert message.startswith("Message: 1 pose stands out (file row 9)"), message
    first_note = next(x for x in captured.out.splitlines() if x.startswith("[1]"))
    assert "file row 9" in first_note, first_note


@pytest.mark.parametrize("encoding", ["utf-16-le", "utf-16-be", "utf-16"])
def test_utf16_is_named(simulated, tmp_path, capsys, encoding):
    """Finding 16: UTF-16 without a byte-order mark gave 'missing column for q1'."""
    path = tmp_path / "utf16.csv"
    path.write_bytes(simulated.encode(encoding))
    assert main(["identify", "puma560", str(path)]) == 2
    err = one_error_line(capsys)
    assert "UTF-16" in err and "save it as UTF-8" in err, err


@pytest.mark.parametrize("line", [1, 2, 5])
def test_a_comment_line_is_refused_by_its_line_number(simulated, tmp_path, capsys, line):
    """Finding 16: a '#' line gave 'some rows have more fields than the header'."""
    lines = simulated.splitlines()
    lines.insert(line - 1, "# exported by the tracker, 2024-05-01, operator: A, B")
    path = tmp_path / "comment.csv"
    path.write_text("\n".join(lines) + "\n")
    assert main(["identify", "puma560", str(path)]) == 2
    err = one_error_line(capsys)
    assert f"line {line} starts with '#'" in err, err


def test_a_hash_inside_a_row_is_data(simulated, tmp_path):
    lines = simulated.splitlines()
    lines = [lines[0] + ",note"] + [x + ",see #3" for x in lines[1:]]
    path = tmp_path / "note.csv"
    path.write_text("\n".join(lines) + "\n")
    meas = cc.read_csv(path, cc.load_robot("puma560"))
    assert meas.n_poses == 60


def test_numbers_are_read_exactly(simulated, tmp_path):
    """Typed columns: the same doubles Python's float() gives for the file's text."""
    path = tmp_path / "sim.csv"
    path.write_text(simulated)
    meas = cc.read_csv(path, cc.load_robot("puma560"))
    lines = simulated.splitlines()
    k = lines[0].split(",").index("y_mm")
    text = [float(x.split(",")[k]) for x in lines[1:]]
    assert np.array_equal(meas.positions[:, 1], np.array(text) * 1e-3)


@pytest.mark.parametrize("value", ["abc", "True", "", "inf", "nan", "NA", "1.5e", "1e400"])
def test_a_bad_value_is_named_with_its_row_across_chunks(simulated, tmp_path, monkeypatch, value):
    monkeypatch.setattr(table, "CHUNK_ROWS", 7)  # the bad row in a later chunk than the first
    lines = simulated.splitlines()
    row = lines[30].split(",")
    row[lines[0].split(",").index("z_mm")] = value
    lines[30] = ",".join(row)
    path = tmp_path / "bad.csv"
    path.write_text("\n".join(lines) + "\n")
    # a number too large for a double reads as inf: the message says what that may have been
    infinite = "'inf' (infinite, or beyond ±1.8e308)"
    shown = {"1e400": infinite, "inf": infinite}
    text = re.escape(shown.get(value, f"'{value}'"))
    with pytest.raises(CalibrationError, match=rf"row 31, column 'z_mm': {text} is not a"):
        cc.read_csv(path, cc.load_robot("puma560"))


def test_out_of_memory_is_one_line_saying_what_fits(simulated, tmp_path, monkeypatch, capsys):
    def no_memory(*args, **kwargs):
        raise MemoryError

    monkeypatch.setattr(table, "_chunks", no_memory)
    path = tmp_path / "sim.csv"
    path.write_text(simulated)
    assert main(["identify", "puma560", str(path)]) == 2
    err = one_error_line(capsys)
    assert "not enough memory to read the file" in err and "MB" in err, err
    if sys.platform == "linux":
        assert "rows would fit" in err, err


MEASURE = """
import os, resource, sys
import casecal as cc
robot = cc.load_robot("puma560")
cc.read_csv(sys.argv[2], robot)  # the first read imports what reading needs
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
meas = cc.read_csv(sys.argv[1], robot)
after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(meas.n_poses, (after - before) * 1024)
"""


@pytest.mark.skipif(sys.platform != "linux", reason="ru_maxrss in kB is Linux's")
def test_reading_costs_at_most_three_times_the_file(simulated, tmp_path):
    """Finding 12: reading cost about 10x the file (1e6 rows, 179 MB: 1.8 GB peak)."""
    head, body = simulated.split("\n", 1)
    path = tmp_path / "big.csv"
    with open(path, "w") as fh:  # 100,000 rows, about 18 MB
        fh.write(head + "\n")
        for _ in range(100_000 // 60 + 1):
            fh.write(body)
    small = tmp_path / "small.csv"  # 420 rows: enough to build the compiled kernels
    small.write_text(head + "\n" + body * 7)
    done = subprocess.run(
        [sys.executable, "-c", MEASURE, str(path), str(small)],
        capture_output=True,
        text=True,
        check=True,
    )
    rows, grew = (int(x) for x in done.stdout.split())
    size = os.path.getsize(path)
    assert rows > 100_000
    assert grew <= 3 * size + 10e6, f"reading {size / 1e6:.0f} MB took {grew / 1e6:.0f} MB more"
