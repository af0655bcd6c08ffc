"""Outputs never destroy what casecal did not write (issue 20, findings 1-4 and 15).

A report folder keeps the user's files; ``-o`` onto a FIFO, a character device or a link
to one writes into it instead of replacing it; the line printed on Ctrl-C names exactly
the files already in place; temporary files of killed runs are swept; a full disk names
the file and leaves no half-built report folder.
"""

from __future__ import annotations

import contextlib
import errno
import os
import signal
import stat
from pathlib import Path

import pytest

from casecal.cli import main
from casecal.textio import write_atomic

USER_FILES = {
    "tracker_export.csv": b"x,y,z\n1,2,3\n",
    "thesis.pdf": b"%PDF-1.4 the user's thesis",
    "setup_photo.png": b"\x89PNG user photo",
    "README.md": b"notes\n",
    "sub/notes.txt": b"deeper notes\n",
}


def _put(folder: Path, files: dict) -> None:
    for name, data in files.items():
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        (folder / name).write_bytes(data)


def _assert_holds(folder: Path, files: dict) -> None:
    for name, data in files.items():
        assert (folder / name).read_bytes() == data, name


def test_report_keeps_the_users_files(tmp_path, fake_report, capsys):
    out = tmp_path / "rep"
    out.mkdir()
    _put(out, USER_FILES)
    assert main(["report", "-o", str(out)]) == 0, capsys.readouterr().err
    _assert_holds(out, USER_FILES)
    _assert_holds(out, fake_report.files)
    assert (out / "casecal-report.pdf").read_bytes() == b"new"
    # the next report drops what the last one wrote and no longer makes, nothing else
    fake_report.files = {"fig1.png": b"newer figure"}
    assert main(["report", "-o", str(out)]) == 0, capsys.readouterr().err
    _assert_holds(out, USER_FILES)
    _assert_holds(out, fake_report.files)
    assert not (out / "table1.csv").exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".rep.")]


def test_report_never_overwrites_a_users_file_of_its_names(tmp_path, fake_report, capsys):
    out = tmp_path / "rep"
    out.mkdir()
    mine = {"fig1.png": b"my own figure", "thesis.pdf": b"thesis"}
    _put(out, mine)
    assert main(["report", "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("casecal: error: ") and err.count("\n") == 1
    assert "fig1.png" in err and "not written by casecal" in err
    _assert_holds(out, mine)
    assert sorted(p.name for p in out.iterdir()) == sorted(mine)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".rep.")]


def test_a_report_folder_from_before_lists_keeps_unknown_files(tmp_path, fake_report, capsys):
    out = tmp_path / "rep"
    out.mkdir()
    _put(out, {"casecal-report.pdf": b"old", "fig1.png": b"old", "old_figure.png": b"old"})
    _put(out, USER_FILES)
    assert main(["report", "-o", str(out)]) == 0, capsys.readouterr().err
    _assert_holds(out, USER_FILES)
    _assert_holds(out, fake_report.files)
    assert (out / "old_figure.png").read_bytes() == b"old"  # not provably ours: kept


def test_report_through_a_link_to_a_folder(tmp_path, fake_report, capsys):
    real = tmp_path / "real"
    real.mkdir()
    _put(real, {"thesis.pdf": b"thesis"})
    link = tmp_path / "link"
    link.symlink_to(real)
    assert main(["report", "-o", str(link)]) == 0, capsys.readouterr().err
    assert link.is_symlink() and link.resolve() == real.resolve()
    _assert_holds(real, {"thesis.pdf": b"thesis", **fake_report.files})
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link", "real"]


@pytest.mark.parametrize(
    "failure",
    [OSError(errno.ENOSPC, "No space left on device", "fig9.png"), KeyboardInterrupt()],
)
def test_a_failed_report_leaves_no_build_folder(tmp_path, fake_report, capsys, failure):
    out = tmp_path / "rep"
    out.mkdir()
    _put(out, {"thesis.pdf": b"thesis"})
    fake_report.fail = failure
    code = main(["report", "-o", str(out)])
    err = capsys.readouterr().err
    assert code == (130 if isinstance(failure, KeyboardInterrupt) else 2), err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rep"]
    _assert_holds(out, {"thesis.pdf": b"thesis"})


@contextlib.contextmanager
def _fifo_reader(path: Path):
    """A FIFO at `path` held open for reading (O_RDWR: never blocks, whatever the
    writer does); yields a function returning what was written into it so far."""
    os.mkfifo(path)
    fd = os.open(path, os.O_RDWR | os.O_NONBLOCK)

    def taken() -> bytes:
        data = b""
        with contextlib.suppress(BlockingIOError):
            while chunk := os.read(fd, 65536):
                data += chunk
        return data

    try:
        yield taken
    finally:
        os.close(fd)


@pytest.mark.parametrize("via_link", [False, True])
def test_simulate_writes_into_a_fifo(tmp_path, capsys, via_link):
    fifo = tmp_path / "pipe"
    with _fifo_reader(fifo) as taken:
        target = fifo
        if via_link:
            target = tmp_path / "link"
            target.symlink_to(fifo)
        code = main(["simulate", "rr", "--poses", "3", "-o", str(target)])
        assert code == 0, capsys.readouterr().err
        assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
        assert taken().startswith(b"q1_deg,q2_deg,x_mm")
    if via_link:
        assert target.is_symlink()
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted({"pipe", target.name})


@pytest.mark.parametrize("through_link", [False, True], ids=["device", "link to a device"])
def test_simulate_to_a_character_device_leaves_it_a_device(tmp_path, capsys, through_link):
    # a private twin of /dev/null (same major, minor), so that a regression can never
    # replace the system's own: the finding was `simulate rr -o /dev/null` as root
    null = tmp_path / "null"
    try:
        os.mknod(null, 0o666 | stat.S_IFCHR, os.makedev(1, 3))
    except (PermissionError, AttributeError, OSError) as exc:
        pytest.skip(f"cannot make a character device here ({exc}); the FIFO tests cover it")
    target = null
    if through_link:
        target = tmp_path / "out.csv"
        target.symlink_to(null)
    assert main(["simulate", "rr", "--poses", "2", "-o", str(target)]) == 0
    assert stat.S_ISCHR(os.lstat(null).st_mode)
    assert os.lstat(null).st_rdev == os.makedev(1, 3)
    if through_link:
        assert target.is_symlink()
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted({"null", target.name})


def test_report_refuses_a_fifo(tmp_path, fake_report, capsys):
    fifo = tmp_path / "pipe"
    with _fifo_reader(fifo):
        assert main(["report", "-o", str(fifo)]) == 2
        assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
    assert capsys.readouterr().err.startswith("casecal: error: ")


@pytest.fixture
def measured(tmp_path):
    csv = tmp_path / "m.csv"
    assert main(["simulate", "rr", "--poses", "12", "-o", str(csv)]) == 0
    return csv


def _interrupt_after_rename_of(monkeypatch, name: str):
    real = os.replace

    def replace(src, dst, *args, **kwargs):
        real(src, dst, *args, **kwargs)
        if Path(dst).name == name:  # Ctrl-C the moment the rename is done
            os.kill(os.getpid(), signal.SIGINT)

    monkeypatch.setattr(os, "replace", replace)


@pytest.mark.parametrize("last", ["out.toml", "dev.csv"])
def test_ctrl_c_after_a_rename_names_what_is_in_place(
    tmp_path, measured, monkeypatch, capsys, last
):
    out, dev = tmp_path / "out.toml", tmp_path / "dev.csv"
    capsys.readouterr()
    _interrupt_after_rename_of(monkeypatch, last)
    argv = ["identify", "rr", str(measured), "--parameters", "a1", "-o", str(out)]
    code = main([*argv, "--deviations-out", str(dev)])
    err = capsys.readouterr().err
    assert code == 130 and err.count("\n") == 1 and err.startswith("casecal: interrupted; ")
    assert "nothing was written" not in err
    # the interrupt lands after every rename of the one write, never between two: both
    # files are in place, whichever rename it came in, and the line names both
    assert str(dev) in err and str(out) in err
    assert dev.exists() and out.exists()


def test_ctrl_c_while_a_csv_is_parsed_is_an_interrupt(tmp_path, measured, monkeypatch, capsys):
    import pandas as pd

    import casecal.data.files as files

    def interrupted(*args, **kwargs):
        # what pandas raises when SIGINT lands in its read of the text (seen with a real
        # Ctrl-C on a 100 MB file: see tests/test_kills.py for the real signal)
        raise pd.errors.ParserError(
            "Error tokenizing data. C error: Calling read(nbytes) on source failed. "
            "Try engine='python'."
        )

    monkeypatch.setattr(files.pd, "read_csv", interrupted)
    capsys.readouterr()
    code = main(["identify", "rr", str(measured), "--parameters", "a1"])
    err = capsys.readouterr().err
    assert code == 130, err
    assert err == "casecal: interrupted; nothing was written\n"


def test_full_disk_names_the_file(tmp_path, monkeypatch, capsys):
    out = tmp_path / "out.csv"
    write_atomic(out, "old\n")  # casecal's own: a command may replace it

    class FullDisk:
        def __init__(self, fh):
            self.fh = fh

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.fh.close()

        def write(self, text):
            raise OSError(errno.ENOSPC, "No space left on device")

    real = os.fdopen
    monkeypatch.setattr(os, "fdopen", lambda *a, **k: FullDisk(real(*a, **k)))
    code = main(["simulate", "rr", "--poses", "3", "-o", str(out)])
    err = capsys.readouterr().err
    assert code == 2, err
    assert err == (
        f"casecal: error: cannot write {str(out)!r}: No space left on device; no file was changed\n"
    )
    assert out.read_text() == "old\n" and os.listdir(tmp_path) == ["out.csv"]


def test_temp_files_of_killed_runs_are_swept(tmp_path, capsys):
    out = tmp_path / "sim.csv"
    dead = _dead_pid()
    stale = [tmp_path / f".sim.csv.casecal-{dead}-a1b2c3d4.tmp"]
    others = [
        tmp_path / f".sim.csv.casecal-{os.getppid()}-zz.tmp",  # a running process's
        tmp_path / ".sim.csv.kq93jd",  # not our pattern (an older casecal, or the user's)
        tmp_path / f".other.csv.casecal-{dead}-a1b2c3d4.tmp",  # another target's
        tmp_path / f"sim.csv.casecal-{dead}-a1b2c3d4.tmp",  # not hidden: not ours
    ]
    for p in stale + others:
        p.write_text("partial")
    assert main(["simulate", "rr", "--poses", "3", "-o", str(out)]) == 0
    assert not any(p.exists() for p in stale)
    assert all(p.read_text() == "partial" for p in others)


def _dead_pid() -> int:
    """The pid of a process that has exited (and been reaped)."""
    pid = os.fork()
    if pid == 0:
        os._exit(0)
    os.waitpid(pid, 0)
    return pid


def test_the_sweep_touches_only_folders_of_exactly_our_names(tmp_path, fake_report, capsys):
    # user folders that look like the sweep's patterns; a name with glob characters
    mine = {
        ".rep.old-backup/important.txt": b"keep",
        ".rep.building-notes-99999/x.txt": b"keep",
        ".rep.old-99999/no_report_here.txt": b"keep",  # a dead pid, but not a report
        ".ra.old-1/f.txt": b"keep",  # would match the glob 'r[ab]'
    }
    _put(tmp_path, mine)
    for out in (tmp_path / "rep", tmp_path / "r[ab]"):
        assert main(["report", "-o", str(out)]) == 0, capsys.readouterr().err
        _assert_holds(out, fake_report.files)
    _assert_holds(tmp_path, mine)
    assert not (tmp_path / "r[ab]" / "f.txt").exists()


def test_a_file_saved_into_the_folder_during_the_swap_is_kept(
    tmp_path, fake_report, capsys, monkeypatch
):
    import casecal.report.folder as folder

    out = tmp_path / "rep"
    assert main(["report", "-o", str(out)]) == 0, capsys.readouterr().err
    swap = folder._exchange

    def exchange(a, b):  # the user saves a file into the report folder at that moment
        (Path(b) / "saved_during_publish.txt").write_bytes(b"precious")
        return swap(a, b)

    monkeypatch.setattr(folder, "_exchange", exchange)
    assert main(["report", "-o", str(out)]) == 0, capsys.readouterr().err
    assert (out / "saved_during_publish.txt").read_bytes() == b"precious"
    _assert_holds(out, fake_report.files)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rep"]


@pytest.mark.parametrize("target", [".", "sub/..", ".."])
def test_report_into_the_folder_you_are_in_is_refused_before_any_study(
    tmp_path, fake_report, capsys, monkeypatch, target
):
    # every target stays inside tmp_path: a regression must not swap a folder of anyone's
    here = tmp_path / "work" / "inner"
    (here / "sub").mkdir(parents=True)
    monkeypatch.chdir(here)
    fake_report.fail = AssertionError("a study ran")
    assert main(["report", "-o", target]) == 2
    err = capsys.readouterr().err
    assert err.startswith("casecal: error: ") and "folder you are in" in err
    assert err.count("\n") == 1
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["inner", "sub", "work"]
