"""The casecal command: useful output, one-line errors with exit code 2."""

from __future__ import annotations

import subprocess
import sys

import pytest

from casecal.cli import main


def test_robots_lists_catalog(capsys):
    assert main(["robots"]) == 0
    out = capsys.readouterr().out
    for name in ("scorbot", "puma560", "kr15_2", "rx90b", "ur5e", "irb120", "scara"):
        assert name in out
    assert "RRPR" in out


def test_show_prints_mm_and_degrees(capsys):
    assert main(["show", "scorbot"]) == 0
    out = capsys.readouterr().out
    assert "349.0000" in out and "221.0000" in out and "145.1250" in out  # d1, a2, d5 in mm
    assert "90.0000" in out  # alpha1 in degrees
    assert "mm" in out and "degrees" in out


@pytest.mark.parametrize("argv", [["show", "nosuchrobot"], ["show", "/no/such/file.toml"]])
def test_user_errors_are_one_line_and_exit_2(capsys, argv):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("casecal: error:")


def test_malformed_robot_file_from_the_shell(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "x"\n[[joints]]\ntype = "R"\na = 1\nalpha = 0\nd = 0\n')
    run = subprocess.run(
        [sys.executable, "-m", "casecal.cli", "show", str(bad)], capture_output=True, text=True
    )
    assert run.returncode == 2
    assert "Traceback" not in run.stderr
    assert "bad.toml" in run.stderr and "convention" in run.stderr
    assert run.stderr.count("\n") == 1


def test_help_answers(capsys):
    with pytest.raises(SystemExit) as info:
        main(["--help"])
    assert info.value.code == 0
    out = capsys.readouterr().out
    assert "robots" in out and "show" in out
