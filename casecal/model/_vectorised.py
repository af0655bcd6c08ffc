"""Evaluate a one-pose CasADi SX Function at many poses with numpy, without a C compiler.

CasADi's own evaluation walks the graph once per pose (about 15 µs per pose for a PUMA's
position Jacobian). Here the Function's instruction list is translated once into Python
source in which every instruction is one numpy operation on a whole batch of poses: a
value that depends on the parameters only stays a Python float (computed once per call,
not per pose), one that depends on the joints is an array over the poses. The work
vector's slots become local variables, so the arrays alive at once are the Function's
work size, and batches are cut to `CHUNK` poses to keep them in cache.

Functions with an operation not in `_BINARY`/`_UNARY` are refused (`Unsupported`); the
caller then falls back to CasADi's evaluation.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

CHUNK = 8192
"""Poses per numpy pass: every live work array (Function.sz_w of them) fits in cache."""


class Unsupported(ValueError):
    """The Function holds an operation this evaluator does not translate."""


_BINARY = {
    ca.OP_ADD: "{0} + {1}",
    ca.OP_SUB: "{0} - {1}",
    ca.OP_MUL: "{0} * {1}",
    ca.OP_DIV: "{0} / {1}",
    ca.OP_POW: "np.power({0}, {1})",
    ca.OP_CONSTPOW: "np.power({0}, {1})",
    ca.OP_ATAN2: "np.arctan2({0}, {1})",
    ca.OP_FMIN: "np.fmin({0}, {1})",
    ca.OP_FMAX: "np.fmax({0}, {1})",
    ca.OP_HYPOT: "np.hypot({0}, {1})",
    ca.OP_COPYSIGN: "np.copysign({0}, {1})",
    ca.OP_FMOD: "np.fmod({0}, {1})",
    ca.OP_LT: "np.less({0}, {1}) * 1.0",
    ca.OP_LE: "np.less_equal({0}, {1}) * 1.0",
    ca.OP_EQ: "np.equal({0}, {1}) * 1.0",
    ca.OP_NE: "np.not_equal({0}, {1}) * 1.0",
    ca.OP_AND: "np.logical_and({0}, {1}) * 1.0",
    ca.OP_OR: "np.logical_or({0}, {1}) * 1.0",
    ca.OP_IF_ELSE_ZERO: "np.where({0} != 0, {1}, 0.0)",
}

_UNARY = {
    ca.OP_ASSIGN: "{0}",
    ca.OP_NEG: "-{0}",
    ca.OP_SQ: "{0} * {0}",
    ca.OP_TWICE: "2.0 * {0}",
    ca.OP_INV: "1.0 / {0}",
    ca.OP_SQRT: "np.sqrt({0})",
    ca.OP_EXP: "np.exp({0})",
    ca.OP_LOG: "np.log({0})",
    ca.OP_SIN: "np.sin({0})",
    ca.OP_COS: "np.cos({0})",
    ca.OP_TAN: "np.tan({0})",
    ca.OP_ASIN: "np.arcsin({0})",
    ca.OP_ACOS: "np.arccos({0})",
    ca.OP_ATAN: "np.arctan({0})",
    ca.OP_SINH: "np.sinh({0})",
    ca.OP_COSH: "np.cosh({0})",
    ca.OP_TANH: "np.tanh({0})",
    ca.OP_FABS: "np.abs({0})",
    ca.OP_SIGN: "np.sign({0})",
    ca.OP_FLOOR: "np.floor({0})",
    ca.OP_CEIL: "np.ceil({0})",
    ca.OP_NOT: "np.logical_not({0}) * 1.0",
}


def source(function: ca.Function) -> str:
    """Python source of ``_evaluate(q, p, out)``: `q` (n_q, N) joint rows, `p` (n_p,),
    `out` (N, n_out) written in place."""
    if function.n_in() != 2 or function.n_out() != 1:
        raise Unsupported("expected a Function (q, p) -> out")
    lines = ["def _evaluate(q, p, out):"]
    for k in range(function.n_instructions()):
        op = function.instruction_id(k)
        o, i = function.instruction_output(k), function.instruction_input(k)
        if op == ca.OP_INPUT:
            # a parameter is a numpy scalar, not a float: 1/0 gives inf as in C, not an error
            source_ = f"q[{i[1]}]" if i[0] == 0 else f"p[{i[1]}]"
            lines.append(f"    w{o[0]} = {source_}")
        elif op == ca.OP_OUTPUT:
            lines.append(f"    out[:, {o[1]}] = w{i[0]}")
        elif op == ca.OP_CONST:
            value = float(function.instruction_constant(k))
            lines.append(f"    w{o[0]} = np.float64({str(value)!r})")
        elif op in _BINARY:
            lines.append(f"    w{o[0]} = " + _BINARY[op].format(f"w{i[0]}", f"w{i[1]}"))
        elif op in _UNARY:
            lines.append(f"    w{o[0]} = " + _UNARY[op].format(f"w{i[0]}"))
        else:
            raise Unsupported(f"CasADi operation {op} has no numpy translation here")
    return "\n".join(lines)


class Vectorised:
    """``(q (N, n_q), p (n_p,)) -> out (N, n_out)`` by numpy, for one SX Function.

    Raises
    ------
    Unsupported
        When the Function uses an operation without a translation.
    """

    def __init__(self, function: ca.Function):
        if not function.is_a("SXFunction"):
            raise Unsupported("only SX Functions have an instruction list to translate")
        code = compile(source(function), f"<casecal {function.name()}>", "exec")
        self._set(code, function.nnz_out(0), function.n_instructions())

    @classmethod
    def from_code(cls, code, n_out: int, n_instructions: int) -> Vectorised:
        """The evaluator whose translated source compiled to `code` (cached on disk,
        `casecal.model._numpy_cache`): no CasADi Function needed."""
        self = cls.__new__(cls)
        self._set(code, n_out, n_instructions)
        return self

    def _set(self, code, n_out: int, n_instructions: int) -> None:
        namespace = {"np": np}
        exec(code, namespace)
        self._evaluate = namespace["_evaluate"]
        self.code, self.n_out, self.n_instructions = code, n_out, n_instructions

    def __call__(self, q: np.ndarray, p: np.ndarray) -> np.ndarray:
        n = q.shape[0]
        out = np.empty((n, self.n_out))
        qT = np.ascontiguousarray(q.T, dtype=float)
        p = np.asarray(p, dtype=float)
        with np.errstate(all="ignore"):  # as in C: inf and nan propagate, nothing raises
            for start in range(0, n, CHUNK):
                stop = min(start + CHUNK, n)
                self._evaluate(qT[:, start:stop], p, out[start:stop])
        return out
