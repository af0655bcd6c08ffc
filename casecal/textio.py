"""Reading and writing text files the way a user's shell expects.

Reading takes ``"-"`` for standard input, pipes and process substitutions, and UTF-8 with
or without a byte-order mark; writing never leaves half a file, follows the umask and
writes through symbolic links. Every failure is one `CalibrationError` line.
"""

from __future__ import annotations

import contextlib
import errno
import os
import re
import stat
import sys
import tempfile
from pathlib import Path

from ._signals import held_signals
from .errors import CalibrationError
from .ownership import check_replaceable, remember


def read_text(path, what: str) -> str:
    """The text of a file (``"-"``: standard input), UTF-8 with or without a byte-order mark.

    Raises `CalibrationError` with one line for a missing, unreadable or binary file.
    """
    data = read_bytes(path, what)
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise CalibrationError(
            f"{what} {str(path)!r} is not UTF-8 text; save it as UTF-8 (CSV or TOML)"
        ) from None


def read_bytes(path, what: str) -> bytes:
    """The bytes of a file (``"-"``: standard input; pipes and process substitutions too).

    Raises `CalibrationError` with one line for a missing, unreadable file or a folder.
    """
    if str(path) == "-":
        return sys.stdin.buffer.read()
    p = Path(path)
    if not p.exists():
        raise CalibrationError(f"{what} {str(path)!r} does not exist; check the path")
    if p.is_dir():
        raise CalibrationError(f"{what} {str(path)!r} is a folder; give a file")
    try:
        with open(p, "rb") as fh:
            return fh.read()
    except OSError as exc:
        raise CalibrationError(f"cannot read {what} {str(path)!r}: {exc.strerror}") from None


def write_atomic(path, text: str) -> None:
    """Write `text` to `path` through a temporary file and a rename: never half a file."""
    write_together([(path, text)])


def write_together(files) -> None:
    """Write several files so that a failure or a kill leaves no half-written one.

    Each text goes to a temporary file beside its target first
    (``.NAME.casecal-<pid>-XXXXXXXX.tmp``); only when all are written are they renamed into
    place, in the order given (put the authoritative file last). A failure while writing
    (a full disk, a folder that is not writable) changes no target. A new file gets the mode
    of the user's umask, a replaced one keeps its own, and a target that is a symbolic link
    is written through: the file it points to is replaced. A character device or a
    FIFO (``/dev/null``, a named pipe, or a link to one) is written into, as the shell's
    ``>`` does, never replaced; ``-``, ``/dev/stdout``, ``/dev/stderr`` and ``/dev/fd/N``
    are written into the open descriptor (``>> log`` appends). A read-only file is refused,
    as the shell refuses it. A target's folder is made if it is one new folder (and removed
    again if nothing could be written). Temporary files that killed runs left beside a target are
    removed (only names of the pattern above whose process no longer runs on this host).

    Each file is recorded (see `recording`) the moment its rename is done, so an
    interrupt can say truly what was written, and registered as casecal's
    (`casecal.ownership`), so that a command may replace it later.

    Parameters
    ----------
    files : sequence of (path, str or bytes)
        Text is written as UTF-8, bytes as they are (a PNG, a program in its own encoding).

    Raises
    ------
    CalibrationError
        An empty name, a folder, a block device or socket, or a write the system refused
        (naming the file and the reason).
    """
    staged, renamed, made = [], [], []
    try:
        targets = [(check_target(path), _bytes(text)) for path, text in files]
        for target, data in targets:
            if not isinstance(target, int) and not _special(target):
                if not target.parent.is_dir() and target.parent.parent.is_dir():
                    target.parent.mkdir()  # one new folder, made as late as this
                    made.append(target.parent)
                _sweep(target)
                staged.append((_stage(target, data), target, data))
        for _, target, _ in staged:
            check_replaceable(target)  # a file that appeared while casecal worked stays
        for target, data in targets:  # may wait for a FIFO's reader: Ctrl-C must work here
            if isinstance(target, int) or _special(target):
                _write_through(target, data)
                _done(renamed, target)
        for _, target, data in staged:
            remember(target, data)  # before the rename: a run beside this one sees it
        with held_signals():  # all renamed and recorded, or (killed) none: never a mix
            for tmp, target, _ in staged:
                os.replace(tmp, target)
                _done(renamed, target)
    except BrokenPipeError:
        raise  # a reader that stopped reading (`| head`): the command's business
    except OSError as exc:
        done = f"; written: {', '.join(renamed)}" if renamed else "; no file was changed"
        name = exc.filename if exc.filename else ""
        raise CalibrationError(f"cannot write {str(name)!r}: {exc.strerror or exc}{done}") from None
    finally:
        for tmp, _, _ in staged:
            Path(tmp).unlink(missing_ok=True)
        for folder in made if not renamed else ():  # nothing written: no folder either
            with contextlib.suppress(OSError):
                folder.rmdir()  # only if empty


def _bytes(text: str | bytes) -> bytes:
    """What is written: bytes as they are, text as UTF-8 with its own line ends."""
    return text if isinstance(text, bytes) else text.encode("utf-8")


_RECORD: list[list[str]] = []


@contextlib.contextmanager
def recording():
    """Collect the paths every write in this block puts in place, as it happens.

    The command line uses it to say, when interrupted, which files were written.
    """
    written: list[str] = []
    _RECORD.append(written)
    try:
        yield written
    finally:
        _RECORD.remove(written)


def record(path) -> None:
    """Note that `path` was written in place (for the innermost `recording` block)."""
    if _RECORD:
        _RECORD[-1].append(str(path))


def _done(renamed: list[str], target) -> None:
    name = DESCRIPTORS.get(target, f"/dev/fd/{target}") if isinstance(target, int) else target
    renamed.append(str(name))
    record(name)


DESCRIPTORS = {1: "/dev/stdout", 2: "/dev/stderr"}

_OPEN_DESCRIPTOR = re.compile(
    r"/dev/(?P<std>stdout|stderr)|/dev/fd/(?P<fd>\d+)"
    r"|/proc/(?P<pid>self|thread-self|\d+)/fd/(?P<pfd>\d+)"
)


def _descriptor(path: str) -> int | None:
    """The open descriptor of this process that `path` names (``/dev/stdout``,
    ``/dev/fd/N``, ``/proc/self/fd/N``), or None. Written through the descriptor itself:
    resolving the link would rename over the file the shell opened (``>> log``)."""
    if path == "-":  # as reading takes it for standard input
        return 1
    where = os.path.abspath(path)  # ../../dev/stdout too
    where = "/" + where.lstrip("/") if where.startswith("//") else where  # POSIX keeps `//`
    match = _OPEN_DESCRIPTOR.fullmatch(where)
    if not match:
        return None
    if match["std"]:
        return 1 if match["std"] == "stdout" else 2
    if match["fd"]:
        return int(match["fd"])
    if match["pid"] not in ("self", "thread-self") and int(match["pid"]) != os.getpid():
        return None  # another process's: an ordinary path
    return int(match["pfd"])


def check_target(path) -> Path | int:
    """Where `write_together` writes `path`: an open descriptor, or the file (a link's
    target). Refuses, in one `CalibrationError` line, what cannot be written as one file:
    an empty name, a name ending in ``/`` (``x/`` is not ``x``), a folder, a link that
    loops, a block device or socket, a read-only file."""
    name = str(path)
    if not name.strip():
        raise CalibrationError("the output file name is empty; give a file name")
    fd = _descriptor(name)
    if fd is not None:
        return fd
    if name.endswith(("/", os.sep)) or os.path.basename(name) in (".", ".."):
        raise CalibrationError(f"{name!r} names a folder, not a file; give a file name")
    path = Path(path)
    if path.is_symlink():
        try:
            path = path.resolve()  # write through the link, keep the link itself
        except (RuntimeError, OSError):  # Python 3.13 raises OSError (ELOOP)
            raise CalibrationError(f"{name!r} is a link that leads back to itself") from None
    if path.is_dir():
        raise CalibrationError(f"{str(path)!r} is a folder; give a file name")
    if path.exists() and not path.is_file() and not _special(path):
        raise CalibrationError(
            f"{str(path)!r} is a block device or a socket, not a file; give a file name"
        )
    if path.is_file() and not os.access(path, os.W_OK):
        raise CalibrationError(  # as the shell's `>` would: read-only is the user's word
            f"{str(path)!r} is read-only; make it writable (chmod u+w) or give another name"
        )
    return path


def written_into(target: Path | int) -> bool:
    """Whether `write_together` writes into `target` (of `check_target`) rather than
    replacing a file: an open descriptor (``-``, ``/dev/stdout``), a FIFO or a character
    device (``/dev/null``)."""
    return isinstance(target, int) or _special(target)


def _special(path: Path) -> bool:
    """A character device or a FIFO: written into, never renamed over."""
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return False
    return stat.S_ISCHR(mode) or stat.S_ISFIFO(mode)


def _write_through(target: Path | int, data: bytes) -> None:
    try:
        if isinstance(target, int):  # the descriptor as the shell opened it (>> appends)
            for stream in (sys.stdout, sys.stderr):  # what was printed before comes first
                if stream is not None:  # None: closed when Python started (`>&-`)
                    stream.flush()
            try:
                while data:
                    data = data[os.write(target, data) :]
            except OverflowError:  # /dev/fd/99999999999: no such descriptor
                raise OSError(errno.EBADF, os.strerror(errno.EBADF)) from None
            return
        with open(target, "wb") as fh:
            fh.write(data)  # a FIFO waits for its reader
    except OSError as exc:
        exc.filename = (
            str(target)
            if not isinstance(target, int)
            else DESCRIPTORS.get(target, f"/dev/fd/{target}")
        )
        raise


def _stage(target: Path, data: bytes) -> str:
    """`data` in a temporary file beside `target`, with a new file's mode; its path."""
    try:
        fd, tmp = tempfile.mkstemp(
            prefix=f".{_stem(target)}.casecal-{os.getpid()}-", suffix=".tmp", dir=target.parent
        )
    except OSError as exc:  # a folder not writable: name the file the user gave
        exc.filename = str(target)
        raise
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.chmod(tmp, _mode(target))
    except OSError as exc:
        Path(tmp).unlink(missing_ok=True)
        exc.filename = str(target)  # the file the user named, not our temporary one
        raise
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return tmp


def _stem(target: Path) -> str:
    """`target`'s name as its temporary files carry it: at most `STEM_BYTES` bytes, so
    that a legal name of up to 255 bytes still has a legal temporary name."""
    return os.fsdecode(os.fsencode(target.name)[:STEM_BYTES])


STEM_BYTES = 200


def _sweep(target: Path) -> None:
    """Remove temporary files of `target` left by casecal runs that were killed."""
    pattern = re.compile(rf"\.{re.escape(_stem(target))}\.casecal-(\d+)-[A-Za-z0-9_]+\.tmp")
    try:
        names = os.listdir(target.parent)
    except OSError:
        return
    for name in names:
        match = pattern.fullmatch(name)
        if match and int(match[1]) != os.getpid() and not alive(int(match[1])):
            Path(target.parent, name).unlink(missing_ok=True)


def alive(pid: int) -> bool:
    """Whether process `pid` runs (one we may not signal counts as running)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):
        return True
    return True


def _mode(target: Path) -> int:
    """The replaced file's own mode (a private file stays private), else a new file's."""
    try:
        return stat.S_IMODE(os.stat(target).st_mode)
    except OSError:
        return 0o666 & ~_umask()


def _umask() -> int:
    mask = os.umask(0o022)  # read it the only portable way, and put it back at once
    os.umask(mask)
    return mask
