"""Commands replace only the files casecal wrote (the second rule; `casecal.ownership`).

An output file that exists and that casecal did not write, or that was changed since it
did, is refused before any work, byte for byte untouched, unless ``--overwrite``; a file
casecal wrote and nobody changed is replaced as before. ``-`` is standard output.
"""

from __future__ import annotations

import pytest

import casecal.ownership as ownership
from casecal.cli import main
from casecal.textio import write_atomic

USERS = b"the user's own file\n"


@pytest.fixture(autouse=True)
def register(tmp_path, monkeypatch):
    """A register of this test's own (the real one is shared by every test process)."""
    path = tmp_path / "cache" / "written"
    monkeypatch.setattr(ownership, "_register", lambda: path)
    return path


@pytest.fixture
def folder(tmp_path, monkeypatch):
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    assert main(["simulate", "rr", "--poses", "60", "--noise", "0.01mm", "-q", "-o", "m.csv"]) == 0
    return work


COMMANDS = {
    "simulate -o": (["simulate", "rr", "--poses", "5", "-o"], "out.csv"),
    "identify -o": (["identify", "rr", "m.csv", "-o"], "cal.toml"),
    "identify --json": (["identify", "rr", "m.csv", "--json"], "r.json"),
    "identify --residuals": (["identify", "rr", "m.csv", "--residuals"], "r.csv"),
    "identify --deviations-out": (["identify", "rr", "m.csv", "--deviations-out"], "d.csv"),
    "validate --json": (["validate", "rr", "m.csv", "--nominal", "rr", "--json"], "v.json"),
    "compensate -o": (["compensate", "rr", "m.csv", "--nominal", "rr", "-o"], "q.csv"),
    "convert OUT": (["convert", "rr"], "rr.toml"),
}


@pytest.mark.parametrize("which", COMMANDS)
def test_a_users_file_is_refused_and_kept_unless_overwrite(folder, capsys, which):
    argv, name = COMMANDS[which]
    target = folder / name
    target.write_bytes(USERS)
    before = sorted(p.name for p in folder.iterdir())
    assert main([*argv, name]) == 2
    err = capsys.readouterr().err
    assert err.startswith("casecal: error: ") and err.count("\n") == 1, err
    assert f"{which.split()[-1]} '{name}' exists and casecal did not write it" in err
    assert "--overwrite" in err
    assert target.read_bytes() == USERS
    assert sorted(p.name for p in folder.iterdir()) == before  # nothing else written

    assert main([*argv, name, "--overwrite"]) == 0, capsys.readouterr().err
    written = target.read_bytes()
    assert written != USERS
    # casecal's own file, unchanged since: replaced without a word
    assert main([*argv, name]) == 0, capsys.readouterr().err
    # changed by hand since: the user's again
    target.write_bytes(written + b"\n")
    assert main([*argv, name]) == 2
    assert "did not write it (or it was changed since)" in capsys.readouterr().err
    assert target.read_bytes() == written + b"\n"


def test_one_users_file_among_the_outputs_stops_the_command_before_any_work(folder, capsys):
    (folder / "r.json").write_bytes(USERS)
    assert main(["identify", "rr", "m.csv", "-o", "cal.toml", "--json", "r.json"]) == 2
    assert "--json 'r.json' exists" in capsys.readouterr().err
    assert not (folder / "cal.toml").exists()
    assert (folder / "r.json").read_bytes() == USERS


def test_a_link_to_a_file_casecal_wrote_is_written_through(folder, capsys):
    (folder / "link.csv").symlink_to(folder / "m.csv")
    assert main(["simulate", "rr", "--poses", "4", "-o", "link.csv"]) == 0
    assert (folder / "link.csv").is_symlink()
    assert len((folder / "m.csv").read_text().splitlines()) == 5
    (folder / "users.csv").write_bytes(USERS)
    (folder / "link2.csv").symlink_to(folder / "users.csv")
    assert main(["simulate", "rr", "--poses", "4", "-o", "link2.csv"]) == 2
    assert (folder / "users.csv").read_bytes() == USERS


def test_dash_is_standard_output_not_a_file_named_dash(folder, capfd):
    capfd.readouterr()
    assert main(["simulate", "rr", "--poses", "3", "-q", "-o", "-"]) == 0
    out = capfd.readouterr().out
    assert out.splitlines()[0].startswith("q1_deg,q2_deg,x_mm") and len(out.splitlines()) == 4
    assert not (folder / "-").exists()


def test_without_a_register_nothing_is_lost_and_the_refusal_says_how(folder, capsys, register):
    (folder / "blocked").write_text("a file where the register's folder would be")
    import casecal.ownership as o

    o._register = lambda: folder / "blocked" / "written"  # undone by the fixture's patch
    assert main(["simulate", "rr", "--poses", "4", "-o", "new.csv"]) == 0
    assert (folder / "new.csv").exists()
    capsys.readouterr()
    assert main(["simulate", "rr", "--poses", "4", "-o", "new.csv"]) == 2
    assert "--overwrite" in capsys.readouterr().err


def test_the_register_keeps_its_newest_lines(tmp_path, monkeypatch, register):
    monkeypatch.setattr(ownership, "REGISTER_BYTES", 3000)
    monkeypatch.setattr(ownership, "REGISTER_KEEP", 5)
    paths = [tmp_path / f"f{i}.txt" for i in range(40)]
    for i, p in enumerate(paths):
        write_atomic(p, f"file {i}\n")
    assert register.stat().st_size <= 3000 + 200
    assert all(ownership.wrote(p) for p in paths[-5:])
    assert not ownership.wrote(paths[0])  # forgotten: a later command refuses, honestly
    paths[-1].write_text("file 39 edited\n")
    assert not ownership.wrote(paths[-1])
    assert not ownership.wrote(tmp_path / "never.txt")
