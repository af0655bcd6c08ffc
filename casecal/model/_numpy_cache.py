"""The numpy evaluator's compiled Python code, cached on disk beside the C kernels.

Where no kernel is compiled (no C compiler, ``CASECAL_BACKEND=numpy``, a Function too long
for GCC such as an elastic humanoid's Jacobian of 100,000 instructions, or one not yet worth
compiling), every new process had built the CasADi Function, translated its instruction
list to Python (`casecal.model._vectorised`) and compiled that: 1.6 s for the humanoid's
Jacobian, every time. Its code object is cached here, as Python caches a module's bytecode,
so a later process loads it in milliseconds without building any CasADi graph.

One file per evaluator, ``casecal_<digest>.numpy``: a line of JSON (the digest of its key,
Python's bytecode magic number, the payload's size, the evaluator's output size and
instruction count, and a SHA-256 over all of them and the payload), then the
zlib-compressed `marshal` of the code. The digest hashes the key (structure, output,
columns) and everything the C kernels' digest covers (`casecal.model._native.fingerprint`:
the model's source, the translator's among it). A file that fails any
check (truncated, flipped bytes in the code or the header, another evaluator's, another
Python's) is removed and rebuilt with one warning; marshal never reads unverified bytes.
Something that is not a regular file in its place is left alone, said once. A cache that
cannot be written costs only the rebuild, said once per process.
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
import logging
import marshal
import os
import tempfile
import types
import zlib
from pathlib import Path

from .._cache import cache_dir
from . import _native

log = logging.getLogger(__name__)

SUFFIX = ".numpy"


def _source_fingerprint() -> str:
    """What a cached code object depends on besides its key."""
    # the model's modules (the translator and this file among them) and Python's bytecode
    text = _native.fingerprint() + importlib.util.MAGIC_NUMBER.hex()
    return hashlib.sha256(text.encode()).hexdigest()


# read at import, as `_native`'s: the files as the code this process runs
_FINGERPRINT = _source_fingerprint()


def _named(key) -> tuple[str, Path]:
    """The digest of evaluator `key` and where its code is cached."""
    digest = hashlib.sha256((_FINGERPRINT + repr(key)).encode()).hexdigest()[:24]
    return digest, cache_dir() / f"casecal_{digest}{SUFFIX}"


def load(key, n_out: int) -> tuple[types.CodeType, int, int] | None:
    """``(code, n_out, n_instructions)`` of evaluator `key` from the cache, or None.

    None when it is not cached, the cache cannot be read, or the file fails a check, one of
    them that it computes `n_out` numbers per pose (then it is removed, with a warning, so
    that the caller's rebuild replaces it).
    """
    try:
        digest, path = _named(key)
        if os.path.lexists(path) and not path.is_file():
            _native._say_once(
                f"{path} is not a regular file; numpy evaluators are translated again in "
                "each process until it is removed",
                log.warning,
                "numpy cache entry",  # not silenced by a failed store's "numpy cache" line
            )
            return None  # a folder or a FIFO is not ours to touch (reading one would wait)
        if not path.is_file():
            return None
        data = path.read_bytes()
    except (OSError, ValueError):
        return None
    found, problem = _verified(data, digest)
    if found is not None and found[1] != n_out:
        found, problem = None, f"{found[1]} outputs instead of {n_out}"
    if found is not None:
        return found
    log.warning("cached numpy evaluator %s is damaged (%s); rebuilding it", path.name, problem)
    try:
        path.unlink()
    except OSError:
        pass
    return None


def _verified(data: bytes, digest: str) -> tuple[tuple | None, str | None]:
    """The cached entry in `data` if every check passes, else (None, why)."""
    head, newline, payload = data.partition(b"\n")
    try:
        record = json.loads(head) if newline else None
    except (ValueError, RecursionError):  # RecursionError: a header nested 10,000 deep
        record = None
    fields = {"key": str, "magic": str, "size": int, "sha256": str, "n_out": int}
    fields["n_instructions"] = int
    if not isinstance(record, dict) or any(type(record.get(f)) is not t for f, t in fields.items()):
        return None, "its header is garbled"
    if record["key"] != digest:
        return None, "it holds another evaluator"
    if record["magic"] != importlib.util.MAGIC_NUMBER.hex():
        return None, "another Python wrote it"
    if len(payload) != record["size"]:
        return None, f"{len(payload)} bytes instead of {record['size']}"
    if _checksum(record, payload) != record["sha256"]:
        return None, "its checksum does not match"
    try:
        code = marshal.loads(zlib.decompress(payload))
    except (ValueError, EOFError, TypeError, zlib.error):
        return None, "its code does not load"
    if not isinstance(code, types.CodeType):
        return None, "it holds no code"
    return (code, record["n_out"], record["n_instructions"]), None


def _checksum(record: dict, payload: bytes) -> str:
    """SHA-256 of `payload` and of every other header field: an edited count is caught
    like a flipped byte of the code."""
    head = {f: record[f] for f in ("key", "magic", "size", "n_out", "n_instructions")}
    return hashlib.sha256(json.dumps(head, sort_keys=True).encode() + payload).hexdigest()


def store(key, code: types.CodeType, n_out: int, n_instructions: int) -> None:
    """Cache evaluator `key`'s `code` (atomically; a failure only costs the next rebuild)."""
    try:
        digest, path = _named(key)
        payload = zlib.compress(marshal.dumps(code), 1)
        record = {
            "key": digest,
            "magic": importlib.util.MAGIC_NUMBER.hex(),
            "size": len(payload),
            "n_out": n_out,
            "n_instructions": n_instructions,
        }
        record["sha256"] = _checksum(record, payload)
        if os.path.lexists(path) and not path.is_file():
            return  # a folder or a special file where ours goes: not ours to replace
        path.parent.mkdir(parents=True, exist_ok=True)
        _native._sweep(path.parent)
        # in a build folder of its own: a killed write leaves what the next sweep removes
        with tempfile.TemporaryDirectory(prefix=_native.BUILD_PREFIX, dir=path.parent) as tmp:
            part = Path(tmp, path.name)
            part.write_bytes(json.dumps(record).encode() + b"\n" + payload)
            os.replace(part, path)
    except (OSError, ValueError) as exc:
        problem = _native._cache_problem(exc, cache_dir()) if isinstance(exc, OSError) else None
        _native._say_once(
            f"numpy evaluators are not cached ({problem or _native._reason(exc)}); "
            "each process translates them again",
            topic="numpy cache",
        )
