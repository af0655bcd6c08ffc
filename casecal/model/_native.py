"""Compile a one-pose CasADi Function to C with a batch loop, cache it on disk, call it by ctypes.

CasADi's own batched call converts every input and output through its DM type, which costs
more than the arithmetic. Here the generated C of the one-pose Function gets a small driver
that loops over the poses in C, and numpy buffers are handed over as pointers, so a batch
costs one Python call. The shared library is cached in ``$CASECAL_CACHE`` or
``~/.cache/casecal`` under a hash of its key (robot structure, output, parameter columns)
and of the code that generates it, so a structure is compiled once per machine and a warm
process loads it without building any CasADi graph. Any failure (no compiler, read-only
cache, compile error) falls back to numpy's evaluation of the same instruction list
(`casecal.model._vectorised`) or CasADi's own, logged but never raised.

A cached library is verified before it is loaded: a sidecar written at build time holds its
size and SHA-256, and the library exports its own key's digest (`casecal_key`), checked
once it is loaded and before any kernel runs. A file truncated by a full disk or a killed
copy, one with flipped bytes, or kernels swapped between files would otherwise crash the
process (SIGBUS, SIGSEGV, SIGILL); instead they are removed and rebuilt, with one warning.
Build folders left behind by a killed compile are swept on the next build.
"""

from __future__ import annotations

import ctypes
import errno
import hashlib
import json
import logging
import os
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import casadi as ca
import numpy as np

from .._cache import cache_dir
from . import _trig

log = logging.getLogger(__name__)

CFLAGS = ("-O3", "-fPIC", "-shared", "-fno-math-errno", "-fno-trapping-math", "-ffp-contract=off")
"""No errno and no floating-point traps to honour (the kernels enable none): GCC then turns
the selects of the joint trigonometry into vector blends. No fused multiply-adds: the
kernels round as numpy does (`casecal.model._trig`), so batch size never changes a bit."""


_DRIVER = """
const char* casecal_key(void) {{ return "{key}"; }}

#define CASECAL_BLOCK {block} /* poses per block: the block's inputs stay under 32 kB */
static const long long casecal_tq[] = {{ {tq} }}; /* per joint angle: its column of q */
static const long long casecal_tp[] = {{ {tp} }}; /* and its offset's index in p */

int casecal_batch(const casadi_real* q, const casadi_real* p, casadi_real* out,
                  long long n_poses) {{
  const casadi_real* arg[{sz_arg}];
  casadi_real* res[{sz_res}];
  casadi_int iw[{sz_iw}];
  casadi_real w[{sz_w}];
  casadi_real qe[CASECAL_BLOCK * {n_qe}], c[CASECAL_BLOCK], s[CASECAL_BLOCK];
  long long k0, i, m, t, nb;
  for (k0 = 0; k0 < n_poses; k0 += CASECAL_BLOCK) {{
    nb = n_poses - k0 < CASECAL_BLOCK ? n_poses - k0 : CASECAL_BLOCK;
    for (i = 0; i < nb; ++i)
      for (m = 0; m < {n_q}; ++m) qe[i * {n_qe} + m] = q[(k0 + i) * {n_q} + m];
    for (t = 0; t < {n_t}; ++t) {{  /* the joints' cos and sin, a block at a time */
      casecal_joint_trig(q + k0 * {n_q} + casecal_tq[t], {n_q}, p[casecal_tp[t]], nb, c, s);
      for (i = 0; i < nb; ++i) {{
        qe[i * {n_qe} + {n_q} + t] = c[i];
        qe[i * {n_qe} + {n_q} + {n_t} + t] = s[i];
      }}
    }}
    for (i = 0; i < nb; ++i) {{
      arg[0] = qe + i * {n_qe};
      arg[1] = p;
      res[0] = out + (k0 + i) * {n_out};
      if ({name}(arg, res, iw, w, 0)) return 1;
    }}
  }}
  return 0;
}}
"""


def compiler() -> str | None:
    """The C compiler to use (``$CC``, else cc or gcc on the PATH), or None."""
    for name in (os.environ.get("CC"), "cc", "gcc", "clang"):
        if name and shutil.which(name):
            return name
    return None


def source(function: ca.Function, key: str = "", n_q: int | None = None, joint_trig=()) -> str:
    """C source of `function` plus the batch driver, which also exports `key`.

    The driver takes `n_q` values per pose (default: the function's first input) and
    appends the cos and sin of each `joint_trig` angle ``q[:, column] + p[index]`` (for
    `casecal.model.kinematics.Chain.joint_trig`) before calling `function` on each pose.
    """
    with tempfile.TemporaryDirectory() as tmp:
        gen = ca.CodeGenerator("kernel.c", {"with_header": False})
        gen.add(function)
        gen.generate(tmp + os.sep)
        text = Path(tmp, "kernel.c").read_text()
    n_qe = function.nnz_in(0)
    n_q = n_qe if n_q is None else n_q
    if n_qe != n_q + 2 * len(joint_trig):
        raise ValueError("internal error: the function's input is not q, cos and sin")
    return (
        text
        + _trig.C_SOURCE
        + _DRIVER.format(
            key=key,
            name=function.name(),
            sz_arg=max(function.sz_arg(), 1),
            sz_res=max(function.sz_res(), 1),
            sz_iw=max(function.sz_iw(), 1),
            sz_w=max(function.sz_w(), 1),
            n_q=n_q,
            n_qe=n_qe,
            block=max(1, min(64, 4096 // max(n_qe, 1))),
            n_t=len(joint_trig),
            tq=", ".join(str(c) for c, _ in joint_trig) or "0",
            tp=", ".join(str(k) for _, k in joint_trig) or "0",
            n_out=function.nnz_out(0),
        )
    )


def _source_fingerprint() -> str:
    """Hash of everything a kernel depends on besides its key: the code that generates it,
    CasADi's version and the compiler flags."""
    # every module of the model: the graph's code, the parameters' layout (p), the terms'
    # helpers (lumped bases, gravity moments) and how a user term's code is keyed; an edit
    # to any of them compiles again rather than risk an old kernel
    files = sorted(Path(__file__).parent.glob("*.py"))
    text = "".join(f.read_text() for f in files)
    text += ca.__version__ + " ".join(CFLAGS)
    return hashlib.sha256(text.encode()).hexdigest()


# read at import, when the files are the code this process runs: one edited later (an
# editable install under development) must not key this process's kernels as the new code's
_FINGERPRINT = _source_fingerprint()


def fingerprint() -> str:
    """Hash of everything a kernel depends on besides its key (`_source_fingerprint`), as
    the code this process imported. Any change gives new cache entries."""
    return _FINGERPRINT


def _named(key) -> tuple[str, Path]:
    """The digest of kernel `key` and where its library is cached."""
    digest = hashlib.sha256((fingerprint() + repr(key)).encode()).hexdigest()[:24]
    return digest, cache_dir() / f"casecal_{digest}.so"


def is_cached(key) -> bool:
    """Whether kernel `key`'s library is in the cache (not yet verified: `kernel` does)."""
    try:
        return _named(key)[1].is_file()
    except (OSError, ValueError):  # an unusable cache folder: `kernel` says why
        return False


def kernel(key, build_function, n_q: int, n_p: int, n_out: int, joint_trig=()):
    """A batch callable ``(q (N, n_q), p (n_p,), out) -> None`` in C, or None.

    Parameters
    ----------
    key : hashable
        Identifies the kernel (robot structure, output kind, parameter columns); with
        `fingerprint` it names the cached library, so a warm cache needs no CasADi graph.
    build_function : callable
        Returns the one-pose CasADi Function; called only when the library must be built.
    n_q, n_p, n_out : int
        Input and per-pose output sizes, checked on every call.
    joint_trig : tuple of (int, int)
        Joint angles whose cos and sin the driver computes (`source`).
    """
    digest, lib_path = _named(key)
    try:
        lib = _load(lib_path, digest)
        if lib is None:
            cc = compiler()
            if cc is None:
                _say_once("no C compiler found; evaluating with numpy (casecal.model._vectorised)")
                return None
            _build(cc, source(build_function(), digest, n_q, joint_trig), lib_path)
            lib = _load(lib_path, digest)
        if lib is None:
            raise OSError(f"the kernel just built at {lib_path} does not verify")
    except NotOurs as exc:
        _say_once(f"{exc}; evaluating with numpy instead", log.warning, "cache")
        return None
    except _CANNOT as exc:
        # every kernel of a read-only cache fails alike: one line per process, not per kernel
        problem = _cache_problem(exc, lib_path.parent)
        message = problem or f"could not compile kernels ({_reason(exc)})"
        _say_once(f"{message}; evaluating with numpy instead", log.warning, "cache")
        return None
    batch = lib.casecal_batch
    batch.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_longlong]
    batch.restype = ctypes.c_int

    def call(q: np.ndarray, p: np.ndarray, out: np.ndarray) -> None:
        q = np.ascontiguousarray(q, dtype=float)
        p = np.ascontiguousarray(p, dtype=float)
        if q.shape[1:] != (n_q,) or p.shape != (n_p,) or out.size != q.shape[0] * n_out:
            raise ValueError("internal error: buffer sizes do not match the kernel")
        if out.dtype != np.float64 or not (out.flags.c_contiguous and out.flags.writeable):
            raise ValueError("internal error: output must be writeable C-contiguous float64")
        status = batch(q.ctypes.data, p.ctypes.data, out.ctypes.data, q.shape[0])
        if status:
            raise RuntimeError(f"compiled kernel {key} returned status {status}")

    return call


class NotOurs(OSError):
    """Something casecal did not write sits where a kernel goes: it is left alone."""


_CANNOT = (OSError, subprocess.CalledProcessError, UnicodeDecodeError, ValueError, RuntimeError)
"""What compiling and loading a kernel may raise: a read-only or full cache, a failing
compiler, a loader message that is not text, CasADi's code generation."""

_SAID: set[str] = set()


def _say_once(message: str, say=None, topic: str | None = None) -> None:
    """Log `message` (info, or with `say`) once per process: every kernel would repeat it.

    Messages of one `topic` count as one (they differ only in the kernel's name).
    """
    if (topic or message) not in _SAID:
        _SAID.add(topic or message)
        (say or log.info)(message)


def _reason(exc: BaseException) -> str:
    """One line for `exc`: a loader's message may hold bytes that are not text."""
    if isinstance(exc, UnicodeDecodeError):
        return "the loader's message is not text"
    return " ".join(str(exc).split())


def _cache_problem(exc: BaseException, folder: Path) -> str | None:
    """What is wrong with the cache `folder` and what to do, if `exc` is about it."""
    code = getattr(exc, "errno", None)
    name = getattr(exc, "filename", None)
    if code is None or isinstance(exc, NotOurs):
        return None
    if name is not None:  # about the folder, a file in it, or a folder above it
        name, top = os.path.abspath(name), str(folder)
        if os.path.commonpath([name, top]) not in (name, top):
            return None  # e.g. the compiler, or the system's temporary folder
    fix = "set CASECAL_CACHE to a writable folder"
    if code in (errno.EEXIST, errno.ENOTDIR):
        for path in (folder, *folder.parents):
            if path.exists() and not path.is_dir():
                why = (
                    "is a file, not a folder"
                    if path == folder
                    else f"cannot be made: {path} is a file"
                )
                return f"kernel cache {folder} {why}; {fix}"
    if code in (errno.EACCES, errno.EPERM, errno.EROFS):
        why = "is not writable" if folder.is_dir() else "cannot be made"
        return f"kernel cache {folder} {why} ({os.strerror(code)}); {fix}"
    if code in (errno.ENOSPC, errno.EDQUOT):
        return f"kernel cache {folder}: {os.strerror(code)}; free some space or {fix}"
    return None


def _load(lib_path: Path, digest: str):
    """The cached library at `lib_path` if it is whole and the right one, else None.

    A library that fails a check is removed (one warning), so the caller rebuilds it.
    """
    if not lib_path.exists():
        return None
    if lib_path.is_dir():
        return _folder_in_place(lib_path)
    for path in (lib_path, _sidecar(lib_path)):
        if path.exists() and not path.is_file():  # reading a FIFO would wait forever
            raise NotOurs(f"{path} is not a regular file; remove it so casecal can rebuild it")
    problem = _damage(lib_path)
    lib = None
    if problem is None:
        try:
            lib = ctypes.CDLL(str(lib_path))
        except (OSError, UnicodeDecodeError, ValueError) as exc:
            # a file whose checksum record was rewritten to match its damage
            problem = f"it does not load: {_reason(exc)}"
    if lib is not None:
        key = getattr(lib, "casecal_key", None)
        if key is None:
            problem = "it exports no kernel key"
        else:
            key.restype = ctypes.c_char_p
            if key() != digest.encode():
                problem = "it holds another robot's kernel"
    if problem is None:
        return lib
    if lib is not None:  # else dlopen would hand back this handle, not the rebuilt file
        _close(lib)
    log.warning("cached kernel %s is damaged (%s); rebuilding it", lib_path.name, problem)
    for path in (lib_path, _sidecar(lib_path)):
        path.unlink(missing_ok=True)
    return None


def _close(lib) -> None:
    """Unload a library that failed its checks (POSIX dlclose; elsewhere it stays)."""
    try:
        import _ctypes

        _ctypes.dlclose(lib._handle)
    except (ImportError, AttributeError, OSError):
        pass


def _folder_in_place(lib_path: Path) -> None:
    """An empty folder where a kernel goes is removed (nothing is lost) so the kernel is
    built; one holding files is not casecal's to delete."""
    try:
        lib_path.rmdir()
    except OSError:
        raise NotOurs(
            f"{lib_path} is a folder, not a compiled kernel; remove it (or set "
            "CASECAL_CACHE to another folder) so that casecal can build its kernels"
        ) from None
    log.warning("cached kernel %s was an empty folder; building it", lib_path.name)


def _damage(lib_path: Path) -> str | None:
    """Why the file at `lib_path` is not the library that was built there, or None."""
    try:
        record = json.loads(_sidecar(lib_path).read_text())
        data = lib_path.read_bytes()
    except (OSError, ValueError):
        return "its size and checksum record is missing"
    if not (
        isinstance(record, dict)
        and type(record.get("size")) is int
        and isinstance(record.get("sha256"), str)
    ):
        return "its size and checksum record is garbled"
    if len(data) != record.get("size"):
        return f"{len(data)} bytes instead of {record.get('size')}"
    if hashlib.sha256(data).hexdigest() != record.get("sha256"):
        return "its checksum does not match"
    return None


def _sidecar(lib_path: Path) -> Path:
    return lib_path.with_suffix(".json")


BUILD_PREFIX = "casecal-build-"
STALE_BUILD = 3600.0
"""Seconds after which a build folder is a killed compile's leftover, not a running one."""


def _build(cc: str, src: str, lib_path: Path) -> None:
    started = time.perf_counter()
    lib_path.parent.mkdir(parents=True, exist_ok=True)
    _sweep(lib_path.parent)
    with tempfile.TemporaryDirectory(prefix=BUILD_PREFIX, dir=lib_path.parent) as tmp:
        c_file = Path(tmp, "kernel.c")
        c_file.write_text(src)
        so_file = Path(tmp, lib_path.name)
        subprocess.run(
            [cc, *CFLAGS, str(c_file), "-o", str(so_file), "-lm"], check=True, capture_output=True
        )
        data = so_file.read_bytes()
        record = Path(tmp, "record.json")
        record.write_text(
            json.dumps({"size": len(data), "sha256": hashlib.sha256(data).hexdigest()})
        )
        # each rename is atomic: a concurrent process sees the old file or the new one
        os.replace(record, _sidecar(lib_path))
        os.replace(so_file, lib_path)
    took = time.perf_counter() - started
    log.info("compiled %s in %.2f s (once per machine)", lib_path.name, took)


def _sweep(folder: Path) -> None:
    """Remove build folders older than `STALE_BUILD`: what killed compiles left."""
    now = time.time()
    for old in folder.glob(f"{BUILD_PREFIX}*"):
        try:
            if now - old.stat().st_mtime > STALE_BUILD:
                shutil.rmtree(old, ignore_errors=True)
        except OSError:
            pass
