"""Commands replace only the files casecal wrote (the second rule; `casecal.ownership`).

An output file that exists and that casecal did not write, or that was changed since it
did, is refused before any work, byte for byte untouched, unless ``--overwrite``; a file
casecal wrote and nobody changed is replaced as before. ``-`` is standard output.
"""

from __future__ import annotations

import os
import signal

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


@pytest.mark.parametrize("argv", [["identify", "rr", "m.csv", "-o"], ["convert", "rr"]])
def test_a_robot_file_to_standard_output_is_refused_in_words(folder, capsys, argv):
    before = sorted(p.name for p in folder.iterdir())
    assert main([*argv, "-"]) == 2
    err = capsys.readouterr().err
    assert "cannot go to standard output ('-')" in err and ".toml" in err, err
    assert sorted(p.name for p in folder.iterdir()) == before


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


@pytest.mark.parametrize("suffix", ["/", "/.", "//"])
def test_a_name_ending_in_a_slash_is_not_the_file_before_it(folder, capsys, suffix):
    (folder / "p.csv").write_bytes(USERS)
    (folder / "link").symlink_to(folder / "p.csv")
    for name in ("p.csv", "link", "m.csv"):  # a user's file, a link to it, an input
        argv = ["identify", "rr", "m.csv", "--json", name + suffix]
        assert main(argv) == 2
        assert "names a folder, not a file" in capsys.readouterr().err
    assert (folder / "p.csv").read_bytes() == USERS


def test_a_file_made_while_the_command_works_is_kept(folder, capsys, monkeypatch):
    import casecal.textio as textio

    sweep = textio._sweep

    def someone_writes(target):  # between the checks before the work and the rename
        if target.name == "cal.toml":
            target.write_bytes(USERS)
        sweep(target)

    monkeypatch.setattr(textio, "_sweep", someone_writes)
    assert main(["identify", "rr", "m.csv", "-o", "cal.toml", "--deviations-out", "d.csv"]) == 2
    assert "made or changed by someone else while casecal worked" in capsys.readouterr().err
    assert (folder / "cal.toml").read_bytes() == USERS
    assert not (folder / "d.csv").exists()  # the calibration's files: together or not at all
    assert not [p for p in folder.iterdir() if ".casecal-" in p.name]


def test_files_are_registered_before_they_are_renamed(folder, capsys, monkeypatch):
    """Ctrl-C the moment a file is in place: it is casecal's, and the next run replaces it."""
    import casecal.textio as textio

    replace = textio.os.replace

    def interrupted_after(tmp, target):
        replace(tmp, target)
        os.kill(os.getpid(), signal.SIGINT)  # held until the renames are done and recorded

    monkeypatch.setattr(textio.os, "replace", interrupted_after)
    assert main(["simulate", "rr", "--poses", "4", "-o", "s.csv"]) == 130
    assert "interrupted; written: " in capsys.readouterr().err
    monkeypatch.setattr(textio.os, "replace", replace)
    assert main(["simulate", "rr", "--poses", "4", "-o", "s.csv"]) == 0


def test_an_error_raised_by_a_ctrl_c_is_an_interrupt(folder, capsys, monkeypatch):
    import casecal.cli.simulate as simulate

    def importing(args):  # as matplotlib turns a Ctrl-C during its import into its own error
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt:
            raise ValueError("matplotlib's own error") from None

    monkeypatch.setattr(simulate, "run", importing)  # the parser is built at each main()
    assert main(["simulate", "rr", "-o", "x.csv"]) == 130
    assert capsys.readouterr().err == "casecal: interrupted; nothing was written\n"


def test_the_register_survives_a_cut_line_a_link_and_odd_names(folder, register, tmp_path):
    register.parent.mkdir(parents=True, exist_ok=True)
    register.write_bytes(b"cut short by a kill")  # no newline at its end
    odd = folder / "cr\rname.csv"
    write_atomic(odd, "a\n")
    assert ownership.wrote(odd)
    assert register.read_bytes().startswith(b"cut short by a kill\n")
    users = tmp_path / "users_notes.txt"
    users.write_bytes(USERS)
    register.unlink()
    register.symlink_to(users)  # never followed: the user's file is not appended to
    write_atomic(folder / "x.csv", "b\n")
    assert users.read_bytes() == USERS and not ownership.wrote(folder / "x.csv")


def test_other_spellings_of_standard_output_are_standard_output(folder, monkeypatch):
    import casecal.textio as textio

    monkeypatch.chdir("/dev")
    for name in ("//dev/stdout", "/proc/thread-self/fd/1", "../dev/stdout", "stdout", "-"):
        assert textio.check_target(name) == 1, name


def test_a_long_legal_name_is_written(folder):
    name = "a" * 250 + ".csv"  # 254 bytes: legal; its temporary name must be too
    assert main(["simulate", "rr", "--poses", "3", "-q", "-o", name]) == 0
    assert (folder / name).read_text().startswith("q1_deg")


def test_a_refused_command_leaves_no_new_folder(folder, capsys):
    (folder / "r.json").write_bytes(USERS)
    assert main(["identify", "rr", "m.csv", "-o", "new/cal.toml", "--json", "r.json"]) == 2
    assert not (folder / "new").exists()
    assert main(["identify", "rr", "m.csv", "-o", "new/cal.toml"]) == 0
    assert (folder / "new" / "cal.toml").is_file()


def test_a_link_that_loops_is_refused_before_the_work(folder, capsys):
    (folder / "loop").symlink_to(folder / "loop")
    assert main(["identify", "rr", "m.csv", "--json", "loop"]) == 2
    err = capsys.readouterr().err
    assert "leads back to itself" in err and "parameter" not in capsys.readouterr().out


def test_writers_of_one_file_at_once_do_not_refuse_each_other(tmp_path):
    import subprocess
    import sys

    argv = [sys.executable, "-m", "casecal", "-q", "simulate", "rr", "-o", "same.csv"]
    runs = [
        subprocess.Popen(
            [*argv, "--poses", str(5 + i)], cwd=tmp_path, stderr=subprocess.PIPE, text=True
        )
        for i in range(10)
    ]
    errors = [run.communicate(timeout=300)[1] for run in runs]
    assert [run.returncode for run in runs] == [0] * 10, errors


def test_standard_output_closed_is_one_line(tmp_path):
    import subprocess
    import sys

    done = subprocess.run(
        [sys.executable, "-m", "casecal", "simulate", "rr", "--poses", "3", "-o", "-"],
        cwd=tmp_path, stderr=subprocess.PIPE, text=True, preexec_fn=lambda: os.close(1),
    )  # fmt: skip
    assert done.returncode == 2 and done.stderr.count("\n") == 1, done.stderr
    assert "cannot write '/dev/stdout'" in done.stderr


def test_an_output_named_like_a_catalog_robot_is_no_input(folder, capsys):
    assert main(["simulate", "rr", "--poses", "4", "-q", "-o", "rr"]) == 0
    assert main(["simulate", "rr", "--poses", "5", "-q", "-o", "rr"]) == 0  # rr: the catalog's
    assert len((folder / "rr").read_text().splitlines()) == 6
    assert main(["convert", "rr", "rr.toml"]) == 0
    capsys.readouterr()
    assert main(["simulate", "./rr.toml", "--poses", "5", "-o", "rr.toml"]) == 2  # a file
    assert "is also the file read as robot" in capsys.readouterr().err


def test_a_register_that_cannot_be_written_is_said_at_once(folder, capsys, monkeypatch):
    (folder / "blocked").write_text("a file where the register's folder would be")
    monkeypatch.setattr(ownership, "_register", lambda: folder / "blocked" / "written")
    monkeypatch.setattr(ownership, "_WARNED", [False])
    assert main(["simulate", "rr", "--poses", "4", "-o", "new.csv"]) == 0
    err = capsys.readouterr().err
    assert "casecal: warning: cannot record 'new.csv' as written by casecal" in err
    assert "without --overwrite" in err and "CASECAL_CACHE" in err


def test_a_refusal_at_the_rename_names_what_was_already_written(folder, capsys, monkeypatch):
    import casecal.textio as textio

    sweep = textio._sweep

    def someone_writes(target):
        if target.name == "cal.toml":
            target.write_bytes(USERS)
        sweep(target)

    monkeypatch.setattr(textio, "_sweep", someone_writes)
    assert main(["identify", "rr", "m.csv", "-o", "cal.toml", "--json", "r.json"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.rstrip().endswith("; already written: r.json"), err
    assert (folder / "cal.toml").read_bytes() == USERS


def test_rewriting_one_file_does_not_push_others_out_of_the_register(tmp_path, monkeypatch):
    monkeypatch.setattr(ownership, "REGISTER_BYTES", 2000)
    monkeypatch.setattr(ownership, "REGISTER_KEEP", 5)
    write_atomic(tmp_path / "kept.txt", "mine to replace later\n")
    for i in range(100):
        write_atomic(tmp_path / "busy.txt", f"version {i}\n")
    assert ownership.wrote(tmp_path / "kept.txt") and ownership.wrote(tmp_path / "busy.txt")


def test_a_descriptor_number_too_large_is_one_line(folder, capsys):
    assert main(["simulate", "rr", "--poses", "3", "-o", "/dev/fd/99999999999999999999"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Bad file descriptor" in err, err


@pytest.mark.parametrize("where", ["before", "after"])
def test_overwrite_before_or_after_the_command(folder, where):
    (folder / "u.csv").write_bytes(USERS)
    argv = ["simulate", "rr", "--poses", "3", "-q", "-o", "u.csv"]
    argv = ["--overwrite", *argv] if where == "before" else [*argv, "--overwrite"]
    assert main(argv) == 0
    assert (folder / "u.csv").read_text().startswith("q1_deg")


def test_a_write_that_fails_leaves_no_new_folder(folder, capsys, monkeypatch):
    import errno

    real = os.fdopen

    def full_disk(fd, *args, **kwargs):
        real(fd, *args, **kwargs).close()
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "fdopen", full_disk)
    assert main(["simulate", "rr", "--poses", "3", "-o", "new/s.csv"]) == 2
    assert "No space left on device; no file was changed" in capsys.readouterr().err
    assert not (folder / "new").exists()
