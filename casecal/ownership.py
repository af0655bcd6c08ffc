"""Which files casecal wrote: so that a command replaces only its own.

A command may replace an output file that casecal itself wrote and nobody changed since
(running ``identify -o cal.toml`` again), but never a file of the user's: a robot file
typed by hand, another tool's CSV, a casecal file edited afterwards. The record is a
register of ``SHA-256 <tab> real path`` lines, one per file written, in the cache folder
(``$CASECAL_CACHE``, else ``~/.cache/casecal``, the kernels' folder), under a name no one
else uses (`REGISTER`); casecal appends to it only while it is a regular file (not a
link). A file is casecal's when its path is registered with the digest of its present
bytes. Lines are appended under a lock that readers share, and the register is trimmed
in place to its newest lines past `REGISTER_BYTES`. Losing it (a cleared cache, another
machine) loses no file: a command then refuses to replace what it wrote earlier and says
how to allow it (``--overwrite``).

The command line checks its outputs before any work (`casecal.cli.outputs`) and, within
`guarded`, `casecal.textio.write_together` checks each again just before it renames the
new file into place (`check_replaceable`): a file that appeared, or was edited, while the
command worked is not replaced either.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import stat
import warnings
from pathlib import Path

from ._cache import cache_dir
from .errors import CalibrationError

REGISTER = "casecal-written-files.tsv"
"""The register's file name in the cache folder."""

REGISTER_BYTES = 1 << 20
"""Past this size the register keeps its newest `REGISTER_KEEP` lines (about 10,000)."""

REGISTER_KEEP = 4000

_GUARD = [False]


@contextlib.contextmanager
def guarded(on: bool = True):
    """Within this block, `check_replaceable` refuses files casecal did not write (a
    command without ``--overwrite``); outside it (the library's own calls) it passes."""
    before = _GUARD[0]
    _GUARD[0] = bool(on)
    try:
        yield
    finally:
        _GUARD[0] = before


def check_replaceable(path) -> None:
    """Refuse, within `guarded`, to replace the regular file `path` if casecal did not
    write it: it appeared, or was changed, after the command checked its outputs."""
    if _GUARD[0] and os.path.isfile(path) and not wrote(path):
        raise CalibrationError(
            f"{str(path)!r} was made or changed by someone else while casecal worked; it is "
            "kept, and the files written with it are not (run again, give another name, or "
            "add --overwrite)"
        )


def _register() -> Path:
    return cache_dir() / REGISTER


def _key(path) -> bytes | None:
    """The register's name of `path`: its real path's bytes; None for a name the
    register's lines cannot hold (a newline or tab in it: then never casecal's)."""
    key = os.fsencode(os.path.realpath(path))
    return None if b"\n" in key or b"\t" in key else key


def _open(flags: int) -> int:
    """The register, opened without following a link; OSError unless a regular file."""
    fd = os.open(_register(), flags | getattr(os, "O_NOFOLLOW", 0), 0o644)
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise OSError(f"{_register()} is not a regular file")
    return fd


def remember(path, data: bytes) -> None:
    """Register that casecal writes `data` to `path` (a regular file).

    Never raises: a register that cannot be written costs only a later refusal to
    replace this file without ``--overwrite``.
    """
    key = _key(path)
    if key is None:
        return
    line = hashlib.sha256(data).hexdigest().encode("ascii") + b"\t" + key
    try:
        _register().parent.mkdir(parents=True, exist_ok=True)
        fd = _open(os.O_RDWR | os.O_APPEND | os.O_CREAT)
        try:
            _lock(fd, exclusive=True)
            lines = _read(fd).split(b"\n")  # the last: b"" or a line cut short by a kill
            if line in lines:
                return  # the same bytes again: one line is enough
            if sum(map(len, lines)) + len(lines) + len(line) > REGISTER_BYTES:
                kept = _newest_per_path([*lines, line])[-REGISTER_KEEP:]
                os.ftruncate(fd, 0)  # trimmed in place, under the lock
                os.write(fd, b"".join(k + b"\n" for k in kept))
            else:
                os.write(fd, (b"\n" if lines[-1] else b"") + line + b"\n")
        finally:
            os.close(fd)  # releases the lock
    except OSError as exc:
        _warn_once(f"cannot record {str(path)!r} as written by casecal in {_register()} "
                   f"({exc.strerror or exc}): a later command will not replace it without "
                   "--overwrite; set CASECAL_CACHE to a writable folder")  # fmt: skip


def _newest_per_path(lines: list[bytes]) -> list[bytes]:
    """`lines` (oldest first) with only the newest line of each path, order kept: the
    file at a path holds its newest bytes, so older digests of it are moot."""
    seen, kept = set(), []
    for line in reversed(lines):
        _, tab, name = line.partition(b"\t")
        if tab and name not in seen:
            seen.add(name)
            kept.append(line)
    return kept[::-1]


_WARNED = [False]


def _warn_once(text: str) -> None:
    if not _WARNED[0]:
        _WARNED[0] = True
        warnings.warn(text, stacklevel=3)


def _lock(fd: int, exclusive: bool) -> None:
    """Hold a whole-file lock on `fd` until it is closed (where the system has flock)."""
    try:
        import fcntl
    except ImportError:  # Windows: one command at a time is the common case
        return
    fcntl.flock(fd, fcntl.LOCK_EX if exclusive else fcntl.LOCK_SH)


def _read(fd: int) -> bytes:
    chunks, offset = [], 0
    while chunk := os.pread(fd, 1 << 20, offset):
        chunks.append(chunk)
        offset += len(chunk)
    return b"".join(chunks)


def wrote(path) -> bool:
    """Whether the regular file `path` holds exactly bytes casecal wrote to it.

    The file is read only if the register names its path (a user's large file is not).
    The register is read again after the file: a command registers its bytes before it
    renames them into place, so whatever the file held when read is in that reading
    (another command may have replaced it meanwhile).
    """
    key = _key(path)
    if key is None or not _digests(key):
        return False
    digest = hashlib.sha256()
    try:
        with open(path, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                digest.update(block)
    except OSError:
        return False
    return digest.hexdigest() in _digests(key)


def _digests(key: bytes) -> set[str]:
    """The digests the register holds for the path `key`."""
    try:
        fd = _open(os.O_RDONLY)
        try:
            _lock(fd, exclusive=False)
            text = _read(fd)
        finally:
            os.close(fd)
    except OSError:
        return set()
    digests = set()
    for line in text.split(b"\n"):  # not splitlines: a name may hold a carriage return
        digest, _, name = line.partition(b"\t")
        if name == key:
            digests.add(digest.decode("ascii", "replace"))
    return digests
