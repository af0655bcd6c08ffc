"""The lack-of-fit test's projections: one QR of [J X r] against their definition."""

from __future__ import annotations

import numpy as np
import pytest

from casecal.identification.lack_of_fit import _explained


def projection(A: np.ndarray, r: np.ndarray) -> tuple[float, int]:
    """|P_A r|² and rank(A) by the definition: a thin SVD of the scaled tall matrix."""
    norms = np.linalg.norm(A, axis=0)
    A = A[:, norms > 0] / norms[norms > 0]
    if A.shape[1] == 0:
        return 0.0, 0
    U, s, _ = np.linalg.svd(A, full_matrices=False)
    rank = int(np.sum(s > s[0] * 1e-9))
    c = U[:, :rank].T @ r
    return float(c @ c), rank


@pytest.mark.parametrize(
    "rows, k_j, k_x", [(3000, 22, 30), (20, 5, 30), (3000, 0, 30), (500, 10, 0), (40, 6, 6)]
)
def test_one_qr_gives_both_projections_and_ranks(rows, k_j, k_x):
    rng = np.random.default_rng(rows + k_j + k_x)
    J = rng.normal(size=(rows, k_j)) * rng.uniform(1e-3, 1e3, k_j)  # metres and radians
    X = rng.normal(size=(rows, k_x))
    if k_j > 3:
        J[:, 3], J[:, 2] = 2 * J[:, 1], 0.0  # a repeated and a blind parameter
    if k_x > 1 and k_j:
        X[:, 0] = J[:, 0] + X[:, 1]  # a smooth error the parameters partly explain
    r = rng.normal(size=rows)
    got = _explained(J, X, r)
    want = [projection(J, r), projection(np.hstack([J, X]), r)]
    for (g, g_rank), (w, w_rank) in zip(got, want, strict=True):
        assert g_rank == w_rank
        assert g == pytest.approx(w, rel=1e-12, abs=1e-12 * float(r @ r))
