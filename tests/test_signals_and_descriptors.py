"""Writes that respect what the shell opened and what the user pressed (issue 20, review).

``-o /dev/stdout`` appends to a ``>>`` file and writes into a pipe instead of renaming over
the file the shell opened; a replaced file keeps its mode; a Ctrl-C between two renames
lands after both; SIGTERM unwinds like Ctrl-C, with one line and exit 143.
"""

from __future__ import annotations

import os
import signal
import stat
import subprocess
import sys
from pathlib import Path

import pytest

import casecal.cli.simulate as simulate_command
from casecal import textio
from casecal.cli import main

SIMULATE = [sys.executable, "-m", "casecal", "simulate", "rr", "--poses", "3", "-o"]


def test_dev_stdout_appends_to_the_file_the_shell_opened(tmp_path):
    log = tmp_path / "log.txt"
    log.write_text("precious line\n")
    inode = log.stat().st_ino
    with open(log, "a") as fh:  # as `casecal … -o /dev/stdout >> log.txt`
        done = subprocess.run([*SIMULATE, "/dev/stdout"], stdout=fh, stderr=subprocess.PIPE)
    assert done.returncode == 0, done.stderr
    text = log.read_text()
    assert text.startswith("precious line\nq1_deg,q2_deg,x_mm")
    assert log.stat().st_ino == inode
    assert sorted(p.name for p in tmp_path.iterdir()) == ["log.txt"]


def test_dev_stdout_into_a_pipe(tmp_path):
    done = subprocess.run([*SIMULATE, "/dev/stdout"], capture_output=True, text=True, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert lines[0].startswith("q1_deg,q2_deg,x_mm") and len(lines) >= 4
    assert any(line.startswith("wrote 3 poses") for line in lines)


def test_a_replaced_file_keeps_its_mode(tmp_path, capsys):
    out = tmp_path / "private.csv"
    textio.write_atomic(out, "old")  # casecal's own: a command may replace it
    out.chmod(0o600)
    assert main(["simulate", "rr", "--poses", "3", "-o", str(out)]) == 0
    assert stat.S_IMODE(out.stat().st_mode) == 0o600
    assert out.read_text().startswith("q1_deg")


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only files, as its shell")
def test_a_read_only_file_is_refused_as_the_shell_refuses_it(tmp_path, capsys):
    out = tmp_path / "kept.csv"
    out.write_text("mine")
    out.chmod(0o444)
    assert main(["simulate", "rr", "--poses", "3", "-o", str(out)]) == 2
    assert "read-only" in capsys.readouterr().err
    assert out.read_text() == "mine"


def test_ctrl_c_between_two_renames_lands_after_both(tmp_path, monkeypatch):
    replace = os.replace
    calls = []

    def replace_then_interrupt(src, dst):
        replace(src, dst)
        calls.append(dst)
        if len(calls) == 1:
            os.kill(os.getpid(), signal.SIGINT)  # the user presses Ctrl-C right there

    monkeypatch.setattr(textio.os, "replace", replace_then_interrupt)
    a, b = tmp_path / "a.txt", tmp_path / "b.txt"
    with textio.recording() as written, pytest.raises(KeyboardInterrupt):
        textio.write_together([(a, "new a"), (b, "new b")])
    assert a.read_text() == "new a" and b.read_text() == "new b"
    assert written == [str(a), str(b)]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt", "b.txt"]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_sigterm_unwinds_like_ctrl_c_with_one_line_and_exit_143(tmp_path, monkeypatch, capsys):
    simulate = simulate_command.simulate

    def simulate_then_terminated(*args, **kwargs):
        os.kill(os.getpid(), signal.SIGTERM)  # a supervisor's `kill` during the work
        return simulate(*args, **kwargs)

    monkeypatch.setattr(simulate_command, "simulate", simulate_then_terminated)
    out = tmp_path / "m.csv"
    assert main(["simulate", "rr", "--poses", "3", "-o", str(out)]) == 143
    assert capsys.readouterr().err == "casecal: terminated; nothing was written\n"
    assert not out.exists() and list(tmp_path.iterdir()) == []
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL


def test_a_path_of_another_process_descriptor_is_an_ordinary_path():
    assert textio._descriptor("/proc/1/fd/1") is None
    assert textio._descriptor(f"/proc/{os.getpid()}/fd/5") == 5
    assert textio._descriptor("/dev/fd/3") == 3
    assert textio._descriptor(str(Path("/dev") / "stdout")) == 1
    assert textio._descriptor("/dev/stdout_backup.csv") is None
