"""`Reduction.folded` (dtpqrt folds of a triangle) against numpy's SVD of the whole matrix.

The R factor and Qᵀr of a tall ``[J | r]`` fold batch by batch; whatever the batch sizes,
and with fewer rows than columns, zero and duplicated columns, they keep every inner
product (``RᵀR = JᵀJ``, ``Rᵀ Qᵀr = Jᵀr``) and the column-scaled singular values.
"""

from __future__ import annotations

import numpy as np
import pytest

from casecal.identification.linalg import FOLD_ROWS, Reduction, column_scales


def _scaled_singular_values(J):
    norms, zero = column_scales(J)
    return np.linalg.svd(np.where(zero, 0.0, J / norms), compute_uv=False)


@pytest.mark.parametrize(
    "k, n, batch",
    [
        (24, 3 * FOLD_ROWS + 17, 12288),  # several folds, a short last one
        (37, 5000, 4096),
        (30, 10, 3),  # fewer rows than columns, batches fewer than the columns
        (30, 40, 7),  # the triangle fills across batches, then dtpqrt takes over
        (5, 3, 2),
        (1, 7, 3),
    ],
)
def test_folded_keeps_the_inner_products_and_singular_values(k, n, batch):
    rng = np.random.default_rng(k * 1000 + n)
    J = rng.normal(size=(n, k)) * np.logspace(0, -6, k)
    if k > 3:
        J[:, 2] = 0.0  # a blind column
        J[:, 3] = 2.0 * J[:, 1]  # a duplicated one
    r = rng.normal(size=n)
    red = Reduction.folded(k, ((J[i : i + batch], r[i : i + batch]) for i in range(0, n, batch)))
    assert red.R.shape == (min(n, k), k) and red.Qtr.shape == (min(n, k),)
    assert red.rows == n and red.rr == pytest.approx(r @ r, rel=1e-13)
    G = J.T @ J
    assert np.abs(red.R.T @ red.R - G).max() <= 1e-13 * np.abs(G).max()
    g = J.T @ r
    assert np.abs(red.R.T @ red.Qtr - g).max() <= 1e-12 * np.abs(J).max() * np.abs(r).sum()
    expected = _scaled_singular_values(J)
    got = np.linalg.svd(red.scaled()[0], compute_uv=False)
    assert np.abs(got[: len(expected)] - expected).max() <= 1e-13
    assert np.all(np.abs(got[len(expected) :]) <= 1e-13)


def test_folded_of_no_columns_keeps_the_residual():
    r = np.arange(5.0)
    red = Reduction.folded(0, [(np.zeros((5, 0)), r)])
    assert red.R.shape == (0, 0) and red.rows == 5 and red.rr == r @ r
