"""Compile a one-pose CasADi Function to C with a batch loop, cache it on disk, call it by ctypes.

CasADi's own batched call converts every input and output through its DM type, which costs
more than the arithmetic. Here the generated C of the one-pose Function gets a small driver
that loops over the poses in C, and numpy buffers are handed over as pointers, so a batch
costs one Python call. The shared library is cached by a hash of its source (which includes
CasADi's version) in ``$CASECAL_CACHE`` or ``~/.cache/casecal``, so a structure is compiled
once per machine. Any failure (no compiler, read-only cache, compile error) falls back to
CasADi's own evaluation, logged but never raised.
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


def compile_function(function: ca.Function):
    """A batch callable ``(q (N, n_q), p, out) -> None`` in C, or None if it cannot be built."""
    cc = compiler()
    if cc is None:
        log.info("no C compiler found; using CasADi's own evaluation")
        return None
    try:
        src = source(function)
        digest = hashlib.sha256((src + " ".join(CFLAGS)).encode()).hexdigest()[:20]
        lib_path = cache_dir() / f"{function.name()}_{digest}.so"
        if not lib_path.exists():
            _build(cc, src, lib_path)
        lib = ctypes.CDLL(str(lib_path))
    except (OSError, subprocess.CalledProcessError) as exc:
        log.warning(
            "could not compile %s (%s); using CasADi's own evaluation", function.name(), exc
        )
        return None
    batch = lib.casecal_batch
    batch.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_longlong]
    batch.restype = ctypes.c_int
    n_q, n_p, n_out = function.nnz_in(0), function.nnz_in(1), function.nnz_out(0)

    def call(q: np.ndarray, p: np.ndarray, out: np.ndarray) -> None:
        q = np.ascontiguousarray(q, dtype=float)
        p = np.ascontiguousarray(p, dtype=float)
        if q.shape[1:] != (n_q,) or p.shape != (n_p,) or out.size != q.shape[0] * n_out:
            raise ValueError("internal error: buffer sizes do not match the kernel")
        if not out.flags.c_contiguous:
            raise ValueError("internal error: output buffer must be C-contiguous")
        status = batch(q.ctypes.data, p.ctypes.data, out.ctypes.data, q.shape[0])
        if status:
            raise RuntimeError(f"compiled {function.name()} returned status {status}")

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
