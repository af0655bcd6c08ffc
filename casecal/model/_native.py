"""Compile a one-pose CasADi Function to C with a batch loop, cache it on disk, call it by ctypes.

CasADi's own batched call converts every input and output through its DM type, which costs
more than the arithmetic. Here the generated C of the one-pose Function gets a small driver
that loops over the poses in C, and numpy buffers are handed over as pointers, so a batch
costs one Python call. The shared library is cached in ``$CASECAL_CACHE`` or
``~/.cache/casecal`` under a hash of its key (robot structure, output, parameter columns)
and of the code that generates it, so a structure is compiled once per machine and a warm
process loads it without building any CasADi graph. Any failure (no compiler, read-only
cache, compile error) falls back to CasADi's own evaluation, logged but never raised.
"""

from __future__ import annotations

import ctypes
import hashlib
import logging
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import casadi as ca
import numpy as np

log = logging.getLogger(__name__)

CFLAGS = ("-O3", "-fPIC", "-shared", "-fno-math-errno")

_DRIVER = """
int casecal_batch(const casadi_real* q, const casadi_real* p, casadi_real* out,
                  long long n_poses) {{
  const casadi_real* arg[{sz_arg}];
  casadi_real* res[{sz_res}];
  casadi_int iw[{sz_iw}];
  casadi_real w[{sz_w}];
  long long k;
  for (k = 0; k < n_poses; ++k) {{
    arg[0] = q + k * {n_q};
    arg[1] = p;
    res[0] = out + k * {n_out};
    if ({name}(arg, res, iw, w, 0)) return 1;
  }}
  return 0;
}}
"""


def cache_dir() -> Path:
    """Where compiled kernels live: ``$CASECAL_CACHE``, else ``~/.cache/casecal``."""
    return Path(os.environ.get("CASECAL_CACHE") or Path.home() / ".cache" / "casecal")


def compiler() -> str | None:
    """The C compiler to use (``$CC``, else cc or gcc on the PATH), or None."""
    for name in (os.environ.get("CC"), "cc", "gcc", "clang"):
        if name and shutil.which(name):
            return name
    return None


def source(function: ca.Function) -> str:
    """C source of `function` plus the batch driver."""
    with tempfile.TemporaryDirectory() as tmp:
        gen = ca.CodeGenerator("kernel.c", {"with_header": False})
        gen.add(function)
        gen.generate(tmp + os.sep)
        text = Path(tmp, "kernel.c").read_text()
    return text + _DRIVER.format(
        name=function.name(),
        sz_arg=max(function.sz_arg(), 1),
        sz_res=max(function.sz_res(), 1),
        sz_iw=max(function.sz_iw(), 1),
        sz_w=max(function.sz_w(), 1),
        n_q=function.nnz_in(0),
        n_out=function.nnz_out(0),
    )


def fingerprint() -> str:
    """Hash of everything a kernel depends on besides its key: the code that generates it,
    CasADi's version and the compiler flags. Any change gives new cache entries."""
    global _FINGERPRINT
    if _FINGERPRINT is None:
        here = Path(__file__).parent
        # parameters.py fixes the layout of p: a change there must not reuse old kernels
        files = ("kinematics.py", "_native.py", "parameters.py")
        text = "".join((here / f).read_text() for f in files)
        text += ca.__version__ + " ".join(CFLAGS)
        _FINGERPRINT = hashlib.sha256(text.encode()).hexdigest()
    return _FINGERPRINT


_FINGERPRINT: str | None = None


def kernel(key, build_function, n_q: int, n_p: int, n_out: int):
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
    """
    digest = hashlib.sha256((fingerprint() + repr(key)).encode()).hexdigest()[:24]
    lib_path = cache_dir() / f"casecal_{digest}.so"
    try:
        if not lib_path.exists():
            cc = compiler()
            if cc is None:
                log.info("no C compiler found; using CasADi's own evaluation")
                return None
            _build(cc, source(build_function()), lib_path)
        lib = ctypes.CDLL(str(lib_path))
    except (OSError, subprocess.CalledProcessError) as exc:
        log.warning(
            "could not compile a kernel for %s (%s); using CasADi's own evaluation", key, exc
        )
        return None
    batch = lib.casecal_batch
    batch.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_longlong]
    batch.restype = ctypes.c_int

    def call(q: np.ndarray, p: np.ndarray, out: np.ndarray) -> None:
        q = np.ascontiguousarray(q, dtype=float)
        p = np.ascontiguousarray(p, dtype=float)
        if q.shape[1:] != (n_q,) or p.shape != (n_p,) or out.size != q.shape[0] * n_out:
            raise ValueError("internal error: buffer sizes do not match the kernel")
        if not out.flags.c_contiguous:
            raise ValueError("internal error: output buffer must be C-contiguous")
        status = batch(q.ctypes.data, p.ctypes.data, out.ctypes.data, q.shape[0])
        if status:
            raise RuntimeError(f"compiled kernel {key} returned status {status}")

    return call


def _build(cc: str, src: str, lib_path: Path) -> None:
    lib_path.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=lib_path.parent) as tmp:
        c_file = Path(tmp, "kernel.c")
        c_file.write_text(src)
        so_file = Path(tmp, lib_path.name)
        subprocess.run(
            [cc, *CFLAGS, str(c_file), "-o", str(so_file), "-lm"], check=True, capture_output=True
        )
        # rename is atomic: a concurrent process sees either no file or a whole one
        os.replace(so_file, lib_path)
    log.info("compiled %s", lib_path)
