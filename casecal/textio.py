"""Reading and writing text files the way a user's shell expects.

Reading takes ``"-"`` for standard input, pipes and process substitutions, and UTF-8 with
or without a byte-order mark; writing never leaves half a file, follows the umask and
writes through symbolic links. Every failure is one `CalibrationError` line.
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

from .errors import CalibrationError


def read_text(path, what: str) -> str:
    """The text of a file (``"-"``: standard input), UTF-8 with or without a byte-order mark.

    Raises `CalibrationError` with one line for a missing, unreadable or binary file.
    """
    if str(path) == "-":
        data = sys.stdin.buffer.read()
    else:
        p = Path(path)
        if not p.exists():
            raise CalibrationError(f"{what} {str(path)!r} does not exist; check the path")
        if p.is_dir():
            raise CalibrationError(f"{what} {str(path)!r} is a folder; give a file")
        try:
            with open(p, "rb") as fh:  # pipes and process substitutions too
                data = fh.read()
        except OSError as exc:
            raise CalibrationError(f"cannot read {what} {str(path)!r}: {exc.strerror}") from None
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise CalibrationError(
            f"{what} {str(path)!r} is not UTF-8 text; save it as UTF-8 (CSV or TOML)"
        ) from None


def write_atomic(path, text: str) -> None:
    """Write `text` to `path` through a temporary file and a rename: never half a file."""
    write_together([(path, text)])


def write_together(files) -> None:
    """Write several files so that a failure or a kill leaves no half-written one.

    Each text goes to a temporary file beside its target first; only when all are
    written are they renamed into place, in the order given (put the authoritative file
    last). A failure while writing (a full disk, a folder that is not writable) changes
    no target. Files get the mode a new file gets under the user's umask, and a target
    that is a symbolic link is written through: the file it points to is replaced.

    Parameters
    ----------
    files : sequence of (path, str)

    Raises
    ------
    CalibrationError
        An empty name, a folder, or a write the system refused (with its reason).
    """
    staged, renamed = [], []
    try:
        for path, text in files:
            target = _target(path)
            staged.append((_stage(target, text), target))
        for tmp, target in staged:
            os.replace(tmp, target)
            renamed.append(str(target))
    except OSError as exc:
        done = f"; written: {', '.join(renamed)}" if renamed else "; no file was changed"
        raise CalibrationError(
            f"cannot write {str(exc.filename or '')!r}: {exc.strerror}{done}"
        ) from None
    finally:
        for tmp, _ in staged:
            Path(tmp).unlink(missing_ok=True)


def _target(path) -> Path:
    if not str(path).strip():
        raise CalibrationError("the output file name is empty; give a file name")
    path = Path(path)
    if path.is_symlink():
        path = path.resolve()  # write through the link, keep the link itself
    if path.is_dir():
        raise CalibrationError(f"{str(path)!r} is a folder; give a file name")
    return path


def _stage(target: Path, text: str) -> str:
    """`text` in a temporary file beside `target`, with a new file's mode; its path."""
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", dir=target.parent or Path("."))
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
        os.chmod(tmp, 0o666 & ~_umask())
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return tmp


def _umask() -> int:
    mask = os.umask(0o022)  # read it the only portable way, and put it back at once
    os.umask(mask)
    return mask
