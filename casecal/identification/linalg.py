"""Small dense linear algebra shared by the solvers, the analysis and the covariance.

Every factorisation here works on column-scaled Jacobians (each column divided by its
norm), so that metres and radians do not decide ranks or cut-offs, and on the small R
factor of a tall Jacobian instead of the Jacobian itself.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def nr_threshold(s: np.ndarray, shape: tuple[int, int]) -> float:
    """Numerical Recipes' singular-value cut-off: ``0.5 √(m + n + 1) · s_max · ε``.

    Singular values below it are rounding noise and are set to zero in the pseudo-inverse
    (Press et al., *Numerical Recipes*, 3rd ed., §2.6), as the paper does.
    """
    m, n = shape
    return 0.5 * np.sqrt(m + n + 1.0) * (s[0] if s.size else 0.0) * np.finfo(float).eps


ZERO_COLUMN = 1e-8
"""A column below this fraction of the largest one is zero: scaling it to unit norm would
turn the rounding it holds (a wrist angle seen through a lever of 1e-17 m) into a full
direction and a step of degrees. The rank tolerance of the analysis, for the same reason."""


def column_scales(J: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Column norms of `J` to scale by, and which columns count as zero (`ZERO_COLUMN`)."""
    norms = np.linalg.norm(J, axis=0)
    zero = norms <= ZERO_COLUMN * max(norms.max(initial=0.0), np.finfo(float).tiny)
    return np.where(zero, 1.0, norms), zero


@dataclass(frozen=True)
class Reduction:
    """A tall weighted least-squares system ``[J | r]`` (rows × k) held by its QR reduction.

    ``[J | r] = Q [R | Qᵀr]`` keeps every inner product of the columns (``JᵀJ = RᵀR``,
    ``Jᵀr = Rᵀ Qᵀr``), so the step, the predicted decrease, the singular values, the null
    space and the covariance of ``min |J z - r|`` follow from the small R, ``Qᵀr`` and
    ``|r|²``; the number of rows is kept for the cut-offs and the degrees of freedom. Rows
    are folded in as they come (`fold`), so a million poses need no tall array in memory.
    Householder QR is column-wise backward stable, so R of the unscaled J, its columns
    scaled afterwards, is as accurate as R of the scaled J; normal equations would square
    the condition number and lose the blind directions below √ε (`RANK_TOLERANCE` is
    1e-8).

    Attributes
    ----------
    R : ndarray, shape (s, k), s ≤ k
        Upper triangular factor of the weighted Jacobian, units of J.
    Qtr : ndarray, shape (s,)
    rr : float
        ``|r|²`` (what the rows hold in all, also what no column explains).
    rows : int
        Rows of the tall system.
    """

    R: np.ndarray
    Qtr: np.ndarray
    rr: float
    rows: int

    @classmethod
    def empty(cls, k: int) -> Reduction:
        return cls(np.zeros((0, k)), np.zeros(0), 0.0, 0)

    @classmethod
    def of(cls, J: np.ndarray, r: np.ndarray) -> Reduction:
        """The reduction of a tall `J` (rows × k) and `r` (rows,)."""
        return cls.empty(J.shape[1]).fold(J, r)

    @classmethod
    def of_blocks(cls, blocks, r: np.ndarray) -> Reduction:
        """`of` for a J given as column blocks side by side (rows × k_i each), written
        once into the factor's work array: no stacked copy of the tall J."""
        m, k = len(r), sum(b.shape[1] for b in blocks)
        work = np.empty((max(m, k + 1), k + 1), order="F")
        work[m:] = 0.0  # zero rows change no R factor
        start = 0
        for b in blocks:
            work[:m, start : start + b.shape[1]] = b
            start += b.shape[1]
        work[:m, k] = r
        Ra = _r_factor(work)
        t = min(m, k)
        return cls(Ra[:t, :k], Ra[:t, k], float(r @ r), m)

    @classmethod
    def from_normal(cls, G: np.ndarray, g: np.ndarray, rr: float, rows: int) -> Reduction | None:
        """The reduction with ``RᵀR = G = JᵀJ`` and ``Rᵀ Qᵀr = g = Jᵀr`` (Cholesky of the
        column-scaled G), or None where the normal equations would lose too much.

        Forming G squares the condition number, so this is offered only where the scaled
        J's is at most `NORMAL_CONDITION` (a step then keeps six or more digits): for the
        steps of the iterated solvers, whose every judgement is made again on a QR pass.
        """
        d = np.sqrt(np.diag(G))
        if not d.size or np.any(d <= ZERO_COLUMN * d.max()):
            return None  # a zero column: the analysis's business, on a QR pass
        Gs = G / np.outer(d, d)
        eig = np.linalg.eigvalsh(Gs)
        if eig[0] <= eig[-1] / NORMAL_CONDITION**2:
            return None
        try:
            L = np.linalg.cholesky(Gs)
        except np.linalg.LinAlgError:
            return None
        return cls(L.T * d, np.linalg.solve(L, g / d), float(rr), int(rows))

    @property
    def k(self) -> int:
        return self.R.shape[1]

    @property
    def norms(self) -> np.ndarray:
        """Column norms of J, shape (k,)."""
        return np.linalg.norm(self.R, axis=0)

    @property
    def rss_out(self) -> float:
        """``|r|² - |Qᵀr|²``: the part of r no combination of the columns explains."""
        return max(self.rr - float(self.Qtr @ self.Qtr), 0.0)

    def fold(self, J: np.ndarray, r: np.ndarray, work: np.ndarray | None = None) -> Reduction:
        """This system with the rows ``[J | r]`` added, shape (m, k) and (m,).

        `work`, a Fortran-ordered array of at least ``k + m`` rows and ``k + 1`` columns,
        is overwritten instead of allocating one.
        """
        k, s, m = self.k, self.R.shape[0], J.shape[0]
        if s + m == 0:
            return self
        if work is None:
            work = np.empty((s + m, k + 1), order="F")
        elif work.shape[1] != k + 1 or work.shape[0] < s + m or not work.flags.f_contiguous:
            raise ValueError(f"work must be Fortran-ordered, at least {s + m} × {k + 1}")
        work[:s, :k], work[:s, k] = self.R, self.Qtr
        work[s : s + m, :k], work[s : s + m, k] = J, r
        work[s + m :] = 0.0  # zero rows change no R factor
        Ra = _r_factor(work)
        t = min(s + m, k)
        return Reduction(Ra[:t, :k], Ra[:t, k], self.rr + float(r @ r), self.rows + int(m))

    @classmethod
    def folded(cls, k: int, batches) -> Reduction:
        """The reduction of every ``(J, r)`` of `batches` (m_i × k, m_i), folded into one
        triangle `FOLD_ROWS` rows at a time.

        Each fold is LAPACK's triangular-pentagonal QR (``dtpqrt``: the QR of the triangle
        ``[R | Qᵀr]`` stacked on the rows, Householder as `fold`), which neither copies nor
        refactors the triangle and works in blocks of `FOLD_BLOCK` columns: 30-40 % less
        time than `fold` per row at 24-37 columns.
        """
        from scipy.linalg import lapack

        red, A, B = cls.empty(k), None, np.empty((FOLD_ROWS, k + 1), order="F")
        block = max(1, min(FOLD_BLOCK, k + 1))
        for J, r in batches:
            for start in range(0, J.shape[0], FOLD_ROWS):
                Jb, rb = J[start : start + FOLD_ROWS], r[start : start + FOLD_ROWS]
                if A is None:
                    # `fold` until R has its k rows: a triangle of fewer rows would need
                    # a rank-revealing step to drop the zero rows dtpqrt leaves inside it
                    red = red.fold(Jb, rb)
                    if red.R.shape[0] == k:
                        A = np.zeros((k + 1, k + 1), order="F")  # [R | Qᵀr]
                        A[:k, :k], A[:k, k] = red.R, red.Qtr
                        rows, rr = red.rows, red.rr
                    continue
                m = len(rb)
                part = B if m == FOLD_ROWS else np.empty((m, k + 1), order="F")
                part[:, :k], part[:, k] = Jb, rb
                A, _, _, info = lapack.dtpqrt(0, block, A, part, overwrite_a=1, overwrite_b=1)
                if info:
                    raise ValueError(f"internal error: LAPACK dtpqrt returned {info}")
                rows, rr = rows + m, rr + float(rb @ rb)
        if A is None:
            return red
        Ra = np.triu(A[:k])  # row k holds what no column explains; `rr` keeps that
        return cls(Ra[:, :k], Ra[:, k], rr, rows)

    def merge(self, other: Reduction) -> Reduction:
        """The system of this one's rows and `other`'s (same columns)."""
        both = self.fold(other.R, other.Qtr)
        return Reduction(both.R, both.Qtr, self.rr + other.rr, self.rows + other.rows)

    def columns(self, index) -> Reduction:
        """The system of the columns `index` of J only (same rows and r)."""
        index = list(index)
        A = np.column_stack([self.R[:, index], self.Qtr])
        Ra = _r_factor(np.asfortranarray(A)) if A.shape[0] > len(index) else A
        t = min(Ra.shape[0], len(index))
        return Reduction(Ra[:t, : len(index)], Ra[:t, len(index)], self.rr, self.rows)

    def scaled(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(R D⁻¹, D, zero)``: R with unit-norm columns (`column_scales`), zero columns 0."""
        norms, zero = column_scales(self.R)
        return np.where(zero, 0.0, self.R / norms), norms, zero

    def solve(self) -> tuple[np.ndarray, float]:
        """``x = D V S⁺ Uᵀ Qᵀr`` of the column-scaled system (`nr_threshold` cut-off) and the
        cost decrease ``0.5 |Qᵀr|² - 0.5 |Qᵀr - R x|²`` the linear model predicts."""
        Rs, norms, _ = self.scaled()
        if Rs.shape[0] == 0:
            return np.zeros(self.k), 0.0
        U, s, Vt = np.linalg.svd(Rs, full_matrices=False)
        keep = s > nr_threshold(s, (self.rows, self.k))
        proj = U[:, keep].T @ self.Qtr
        z = Vt[keep].T @ (proj / s[keep])
        return z / norms, 0.5 * float(proj @ proj)

    def decrease_at_size(self) -> float:
        """`solve`'s cost decrease, except that where the columns can explain the whole
        residual by shrinking the robot, that one direction is left out.

        Data of contact sessions only (`casecal.identification.contact`) are 0 by
        construction, so the model's own points are the residuals, and scaling every
        length down (the size, which contacts cannot see) explains all of them, noise
        included: freeing parameters that complete that direction would "lower the cost"
        by all of it. What they could explain at the robot's size is the decrease over
        the columns' other directions (the size direction's complement, column-scaled).
        """
        z, total = self.solve()
        if self.rr <= 0 or 2.0 * total < (1.0 - SIZE_SPAN) * self.rr:
            return total
        Rs, norms, _ = self.scaled()
        v = z * norms  # the size direction, scaled coordinates
        if not np.any(v):
            return total
        basis = np.linalg.svd(v[None, :])[2][1:].T  # (k, k - 1): v's complement
        A = Rs @ basis
        U, s, _ = np.linalg.svd(A, full_matrices=False)
        keep = s > nr_threshold(s, (self.rows, A.shape[1])) if s.size else s > 0
        proj = U[:, keep].T @ self.Qtr
        return 0.5 * float(proj @ proj)


SIZE_SPAN = 1e-6
"""Fraction of the residual's square a linear step may leave for `decrease_at_size` to
take the columns for explaining all of it (by the robot's size)."""

FOLD_ROWS = 2048
"""Rows folded per factorisation in `Reduction.folded`: they stay in the cache (6144 are
15 % slower per row at 24 columns; 1024 to 3072 are alike)."""

FOLD_BLOCK = 6
"""Columns per block of `Reduction.folded`'s ``dtpqrt`` (4 to 8 are alike at 24 and 37
columns; 12 is 20 % and a whole-width block 50-80 % slower)."""

NORMAL_CONDITION = 1e5
"""Largest condition number of the column-scaled Jacobian for which a solver's step may
come from the normal equations (`Reduction.from_normal`): their 1e10 leaves six digits."""


def _r_factor(A: np.ndarray) -> np.ndarray:
    """The R factor (min(m, n) × n) of a Fortran-ordered `A`, which it overwrites."""
    from scipy.linalg import lapack

    qr, _, _, info = lapack.dgeqrf(A, overwrite_a=True)
    if info:
        raise ValueError(f"internal error: LAPACK dgeqrf returned {info}")
    return np.triu(qr[: min(A.shape)])  # a copy: `A` may be reused


def svd_solve(J, r: np.ndarray | None = None) -> np.ndarray:
    """``x = D V S⁺ Uᵀ r`` for the column-scaled ``J D``: the paper's SVD least squares.

    `J` is a tall Jacobian with its residual `r`, or a `Reduction` (then no `r`); computed
    on the R factor either way (same singular values and V).
    """
    return _reduction(J, r).solve()[0]


def gauss_newton_step(J, r: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """The Gauss-Newton step of the scaled problem and the cost decrease it predicts.

    Parameters
    ----------
    J : ndarray, shape (rows, k), or Reduction
        Weighted Jacobian (with `r`), or a `Reduction` of both.
    r : ndarray, shape (rows,), optional

    Returns
    -------
    step : ndarray, shape (k,)
        `svd_solve` of ``J`` and ``r``.
    predicted : float
        ``0.5 |r|² - 0.5 |r - J step|²`` of the linear model: what one more step could
        still gain. Zero at a minimum; the convergence and optimality tests use it.
    """
    return _reduction(J, r).solve()


def _reduction(J, r) -> Reduction:
    return J if isinstance(J, Reduction) else Reduction.of(J, r)
