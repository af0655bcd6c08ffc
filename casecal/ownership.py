"""Which files casecal wrote: so that a command replaces only its own.

A command may replace an output file that casecal itself wrote and nobody changed since
(running ``identify -o cal.toml`` again), but never a file of the user's: a robot file
typed by hand, another tool's CSV, a casecal file edited afterwards. The record is a
register of ``SHA-256 <tab> real path`` lines, one per file written, in the cache folder
(``$CASECAL_CACHE``, else ``~/.cache/casecal``, the kernels' folder). A file is casecal's
when its path is registered with the digest of its present bytes. Lines are appended
under a lock that readers share, and the register is trimmed in place to its newest
lines past `REGISTER_BYTES`. Losing it (a cleared cache, another machine) loses no file:
a command then refuses to replace what it wrote earlier and says how to allow it
(``--overwrite``).
"""

from __future__ import annotations

import hashlib
import logging
import os
from pathlib import Path

from ._cache import cache_dir

log = logging.getLogger(__name__)

REGISTER = "written"
"""The register's file name in the cache folder."""

REGISTER_BYTES = 1 << 20
"""Past this size the register keeps its newest `REGISTER_KEEP` lines (about 10,000)."""

REGISTER_KEEP = 4000


def _register() -> Path:
    return cache_dir() / REGISTER


def _key(path) -> str:
    return os.path.realpath(path)


def remember(path, data: bytes) -> None:
    """Register that casecal wrote `data` to `path` (a regular file, now in place).

    Never raises: a register that cannot be written costs only a later refusal to
    replace this file without ``--overwrite``.
    """
    key = _key(path)
    if "\n" in key or "\t" in key:
        return  # a name the register's lines cannot hold: treated as not casecal's
    line = f"{hashlib.sha256(data).hexdigest()}\t{key}\n".encode("utf-8", "surrogateescape")
    register = _register()
    try:
        register.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(register, os.O_RDWR | os.O_APPEND | os.O_CREAT, 0o644)
        try:
            _lock(fd, exclusive=True)
            os.write(fd, line)
            if os.fstat(fd).st_size > REGISTER_BYTES:  # trimmed in place, under the lock
                kept = _read(fd).splitlines(keepends=True)[-REGISTER_KEEP:]
                os.ftruncate(fd, 0)
                os.write(fd, b"".join(kept))
        finally:
            os.close(fd)  # releases the lock
    except OSError as exc:
        log.debug("cannot record %s as written by casecal in %s: %s", key, register, exc)


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
    """
    key = _key(path).encode("utf-8", "surrogateescape")
    try:
        fd = os.open(_register(), os.O_RDONLY)
        try:
            _lock(fd, exclusive=False)
            text = _read(fd)
        finally:
            os.close(fd)
    except OSError:
        return False
    digests = {
        line.partition(b"\t")[0].decode("ascii", "replace")
        for line in text.splitlines()
        if line.partition(b"\t")[2] == key
    }
    if not digests:
        return False
    digest = hashlib.sha256()
    try:
        with open(path, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                digest.update(block)
    except OSError:
        return False
    return digest.hexdigest() in digests
