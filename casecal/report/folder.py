"""Build the report beside its folder and swap it in whole, never losing the user's files.

A report killed halfway must not leave a truncated PDF in place of the old one, nor a
folder that mixes new figures with an old PDF. So the report is built in a hidden folder
next to the target (``.reports.building-<pid>``) and swapped in at the end: on Linux with
one atomic ``renameat2(RENAME_EXCHANGE)``, elsewhere with two renames. After a kill at any
moment the target holds the old report or the new one, whole. Build folders of killed
runs are removed by the next one, and so is the build folder of a run that fails.

What the report may replace or remove: only what it wrote. Each report lists the names it
wrote in a hidden file ``.casecal-report`` in its folder. When a new report is published:

- the files the last report listed are replaced by the new ones, or dropped if the new
  report no longer makes them;
- everything else in the folder (a README, the user's ``thesis.pdf``, a tracker export,
  sub-folders) is carried over untouched (hard-linked into the new folder, copied where
  links are impossible);
- a file the last report did not list but whose name the new report writes is never
  overwritten: the report is refused, saying which file to move. A folder written by a
  casecal from before these lists (it holds ``casecal-report.pdf`` but no
  ``.casecal-report``) counts as a report folder: files with the names the new report
  writes are replaced, every other file is kept.

The output may be a new folder, an empty one, a report folder, a folder of the user's
files, or a symbolic link to a folder (the folder it points to is written); anything
else (a file, a device, a FIFO) is refused.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import os
import re
import shutil
import stat
from pathlib import Path

from .._signals import held_signals
from ..errors import CalibrationError
from ..textio import alive, record

MANIFEST = ".casecal-report"
"""The hidden file listing, one name a line, what the report in this folder wrote."""

PDF = "casecal-report.pdf"


def building_folder(out: Path, names=()) -> Path:
    """A new, empty folder beside `out` to build the report in (stale ones removed).

    Refuses, before any work, an `out` that is not a folder or whose parent folder does not
    exist, and one that holds a file the report did not write under one of `names` (the
    names the report will write, as far as known: `publish` checks what it did write).
    `out` itself is only made when the report is published.
    """
    out = _resolved(out)
    if not out.parent.is_dir():
        raise CalibrationError(
            f"cannot make the report folder {str(out)!r}: {str(out.parent)!r} does not exist "
            "either (check the path, or create the folders first)"
        )
    _sweep(out)
    if out.exists():
        _refuse_foreign(out, {PDF, *names})
    folder = out.parent / f".{out.name}.building-{os.getpid()}"
    if _ours_to_sweep(folder):
        shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir()
    (folder / MANIFEST).touch()  # marks the folder as ours, for a later run's sweep
    return folder


def discard(folder: Path) -> None:
    """Remove a build folder whose report failed or was interrupted."""
    if _ours_to_sweep(Path(folder)):
        shutil.rmtree(folder, ignore_errors=True)


def publish(folder: Path, out: Path) -> None:
    """Make `folder` (a finished report) the content of `out` at once, keeping the files
    in `out` that no report wrote (see the module's text)."""
    out = _resolved(out)
    new = {p.name for p in Path(folder).iterdir()} - {MANIFEST}
    (Path(folder) / MANIFEST).write_text("".join(f"{name}\n" for name in sorted(new)))
    replaced = {MANIFEST}  # names in `out` the new report replaces or drops
    if out.exists():
        _refuse_foreign(out, new)
        ours = _ours(out)
        for item in out.iterdir():
            if item.name in new or item.name == MANIFEST or (ours and item.name in ours):
                replaced.add(item.name)  # the old report's
                continue
            _carry(item, Path(folder) / item.name)
    with held_signals():  # a Ctrl-C after the swap still says the report was written
        if not out.exists():
            os.rename(folder, out)
            folder = None
        elif _exchange(folder, out):
            pass  # `folder` now holds the old report
        else:
            old = out.parent / f".{out.name}.old-{os.getpid()}"
            os.rename(out, old)
            os.rename(folder, out)
            folder = old
        record(out)
    if folder is not None:
        _clear_old(folder, out, replaced)


def _clear_old(old: Path, out: Path, replaced: set[str]) -> None:
    """Empty the folder that holds the old report after the swap, by name: the old report's
    files, and what was carried (linked or copied into `out`). Anything else appeared in
    the old folder while the report was published: it is moved into `out`, or, where `out`
    has that name, the old folder is kept beside `out` (and said so)."""
    # the marks of a report folder go last: a kill halfway leaves a folder the sweep knows
    for item in sorted(old.iterdir(), key=lambda p: p.name in (MANIFEST, PDF)):
        if item.name in replaced or os.path.lexists(out / item.name):
            carried = item.name not in replaced
            if carried and not _same(item, out / item.name):
                continue  # not what was carried: kept below
            if item.is_dir() and not item.is_symlink():
                shutil.rmtree(item, ignore_errors=True)
            else:
                item.unlink(missing_ok=True)
        else:
            os.rename(item, out / item.name)
    try:
        old.rmdir()
    except OSError:
        kept = out.parent / f".{out.name}.kept-{os.getpid()}"
        os.rename(old, kept)
        raise CalibrationError(
            f"the report is in {str(out)!r}; files that changed in it while it was published "
            f"are kept in {str(kept)!r}: compare them and move what you need"
        ) from None


def _same(a: Path, b: Path) -> bool:
    """Whether `b` is what `_carry` made of `a`: the same file (a hard link), a copy of the
    same size and time, a link to the same place, or a folder."""
    try:
        sa, sb = os.lstat(a), os.lstat(b)
    except OSError:
        return False
    if stat.S_ISLNK(sa.st_mode):
        return stat.S_ISLNK(sb.st_mode) and os.readlink(a) == os.readlink(b)
    if stat.S_ISDIR(sa.st_mode):
        return stat.S_ISDIR(sb.st_mode)
    return (sa.st_ino, sa.st_dev) == (sb.st_ino, sb.st_dev) or (
        sa.st_size == sb.st_size and int(sa.st_mtime) == int(sb.st_mtime)
    )


def _resolved(out) -> Path:
    """`out` as an absolute path, or the folder a symbolic link `out` points to; refuses
    anything not a folder, and the working folder or one above it (the swap would move the
    folder the user is in, and the build folder would be copied into itself)."""
    out = Path(os.path.abspath(out))
    if out.is_symlink():
        out = out.resolve()
    # through links too: the folder the user is in must not be swapped away from under them
    real, here = Path(os.path.realpath(out)), Path(os.path.realpath(os.getcwd()))
    if real == here or real in here.parents or not out.name:
        raise CalibrationError(
            f"-o {str(out)!r} is the folder you are in (or one above it); the report replaces "
            "its folder as a whole: give a folder for it, e.g. -o reports"
        )
    if out.exists() and not out.is_dir():
        raise CalibrationError(
            f"{str(out)!r} is not a folder (a file, a device or a FIFO); "
            "give a new or existing folder with -o"
        )
    return out


def _ours(out: Path) -> set[str] | None:
    """Names the report in `out` wrote: its list; None for a report from before lists
    (any name the new report writes); empty for a folder no report wrote."""
    try:
        text = (out / MANIFEST).read_text(encoding="utf-8")
    except FileNotFoundError:
        return None if (out / PDF).is_file() else set()
    except (OSError, UnicodeDecodeError):
        return set()  # an unreadable list claims nothing
    return {n for n in text.splitlines() if n and "/" not in n and n not in (".", "..")}


def _refuse_foreign(out: Path, names) -> None:
    ours = _ours(out)
    if ours is None:
        return
    for name in sorted(names):
        if name not in ours and os.path.lexists(out / name):
            raise CalibrationError(
                f"{str(out / name)!r} was not written by casecal, and the report writes a "
                "file of that name; move that file, or give another folder with -o"
            )


def _carry(item: Path, to: Path) -> None:
    """Put `item` (kept from the old folder) at `to` in the new one without copying
    its bytes where a hard link can do."""
    if item.is_symlink():
        os.symlink(os.readlink(item), to)
    elif item.is_dir():
        shutil.copytree(item, to, symlinks=True, copy_function=_link)
    else:
        _link(item, to)


def _link(src, dst) -> None:
    try:
        os.link(src, dst, follow_symlinks=False)
    except OSError:
        if not stat.S_ISREG(os.lstat(src).st_mode):  # reading a FIFO would wait forever
            raise CalibrationError(
                f"cannot keep {str(src)!r} (not a regular file) in the new report folder; "
                "move it, or give another folder with -o"
            ) from None
        shutil.copy2(src, dst)


def _exchange(a: Path, b: Path) -> bool:
    """Swap two paths atomically (Linux renameat2 RENAME_EXCHANGE); False if unsupported."""
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name, use_errno=True)
        renameat2 = libc.renameat2
    except (OSError, AttributeError, TypeError):
        return False
    at_fdcwd, rename_exchange = -100, 2
    done = renameat2(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), rename_exchange)
    return done == 0


SWEPT = re.compile(r"\.(?P<name>.+)\.(?P<kind>building|old)-(?P<pid>\d+)")
"""Build folders (and old reports of the two-rename fallback) that runs leave beside `out`."""


def _sweep(out: Path) -> None:
    """Remove build folders of report runs that are no longer running, and put back an old
    report a killed fallback swap left aside. Only folders of exactly our names are
    touched, and only those holding our list (`MANIFEST`) or a report PDF."""
    for name in os.listdir(out.parent):
        match = SWEPT.fullmatch(name)
        if not match or match["name"] != out.name:
            continue
        folder, pid = out.parent / name, int(match["pid"])
        if pid != os.getpid() and alive(pid):
            continue
        if not _ours_to_sweep(folder):
            with contextlib.suppress(OSError):  # killed before its mark: empty, so removable
                folder.rmdir()
            continue
        if match["kind"] == "old" and not out.exists():
            os.rename(folder, out)  # killed between the fallback's two renames: it comes back
        else:
            shutil.rmtree(folder, ignore_errors=True)


def _ours_to_sweep(folder: Path) -> bool:
    """A real folder (not a link) that a report run made: it holds our list or a PDF."""
    return (
        folder.is_dir()
        and not folder.is_symlink()
        and ((folder / MANIFEST).is_file() or (folder / PDF).is_file())
    )
