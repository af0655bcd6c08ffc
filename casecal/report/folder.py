"""Build the report beside its folder and swap it in whole.

A report killed halfway must not leave a truncated PDF in place of the old one, nor a
folder that mixes new figures with an old PDF. So the report is built in a hidden folder
next to the target (``.reports.building-<pid>``) and swapped in at the end: on Linux with
one atomic ``renameat2(RENAME_EXCHANGE)``, elsewhere with two renames. After a kill at any
moment the target holds the old report or the new one, whole. Files in the target that the
report does not make (a README, the user's own notes) are carried over; build folders of
killed runs are removed by the next one.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import shutil
from pathlib import Path

REPORT_SUFFIXES = {".pdf", ".png", ".csv"}
"""What a report writes; anything else in the target folder is the user's and is kept."""


def building_folder(out: Path) -> Path:
    """A new, empty folder beside `out` to build the report in (stale ones removed)."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    _sweep(out)
    folder = out.parent / f".{out.name}.building-{os.getpid()}"
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir()
    return folder


def publish(folder: Path, out: Path) -> None:
    """Make `folder` (a finished report) the content of `out`, at once."""
    out = Path(out)
    if out.exists():
        for item in out.iterdir():
            if item.suffix not in REPORT_SUFFIXES and not (folder / item.name).exists():
                if item.is_dir():
                    shutil.copytree(item, folder / item.name, symlinks=True)
                else:
                    shutil.copy2(item, folder / item.name)
    if not out.exists():
        os.rename(folder, out)
    elif _exchange(folder, out):
        shutil.rmtree(folder, ignore_errors=True)  # it now holds the old report
    else:
        old = out.parent / f".{out.name}.old-{os.getpid()}"
        os.rename(out, old)
        os.rename(folder, out)
        shutil.rmtree(old, ignore_errors=True)


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


def _sweep(out: Path) -> None:
    """Remove build folders of report runs that are no longer running."""
    for folder in out.parent.glob(f".{out.name}.building-*"):
        try:
            pid = int(folder.name.rsplit("-", 1)[1])
        except ValueError:
            continue
        if pid == os.getpid() or not _alive(pid):
            shutil.rmtree(folder, ignore_errors=True)
    for folder in out.parent.glob(f".{out.name}.old-*"):
        if out.exists():
            shutil.rmtree(folder, ignore_errors=True)
        else:  # killed between the two renames of the fallback: the old report comes back
            os.rename(folder, out)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True
