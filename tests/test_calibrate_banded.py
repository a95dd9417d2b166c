"""calibrate.banded.BorderedBanded against dense numpy linear algebra (the oracle): solves,
log-determinants and the selected inverse of random SPD bordered-banded matrices."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import sparse

from rafostrack.calibrate.banded import BorderedBanded, transposed_product

# (band unknowns n, half-bandwidth b, border size m): narrow and wide bands, no border, a
# border larger than the band, and the smoother's own layout (6 unknowns a node, b = 11).
CASES = [(30, 1, 0), (30, 1, 3), (40, 3, 5), (25, 6, 12), (60, 11, 9), (12, 11, 2), (50, 0, 4)]


def _bordered_banded(n: int, b: int, m: int, seed: int) -> np.ndarray:
    """A dense SPD N = [[B, C], [C', E]] with B of half-bandwidth exactly b: B = L L' + I
    (L lower banded), C random, E = C' B^-1 C + S (S SPD), so the Schur complement is S.
    Scaled unevenly, as a normal matrix of mixed units is."""
    rng = np.random.default_rng(seed)
    low = np.tril(np.triu(rng.normal(size=(n, n)), -b))
    band = low @ low.T + np.eye(n)
    border = rng.normal(size=(n, m))
    s = rng.normal(size=(m, m))
    corner = border.T @ np.linalg.solve(band, border) + s @ s.T + 0.5 * np.eye(m)
    dense = np.block([[band, border], [border.T, corner]])
    scale = np.exp(rng.uniform(-3.0, 3.0, n + m))
    return scale[:, None] * dense * scale[None, :]


def _factor(dense: np.ndarray, n: int, b: int, fmt: str = "csr") -> BorderedBanded:
    return BorderedBanded(sparse.csr_matrix(dense).asformat(fmt), n, b)


@pytest.mark.parametrize(("n", "b", "m"), CASES)
def test_solve_and_log_det_match_dense_numpy(n, b, m):
    dense = _bordered_banded(n, b, m, seed=n + 7 * b + 31 * m)
    assert np.abs(np.tril(dense[:n, :n], -b - 1)).max(initial=0.0) == 0.0
    assert b == 0 or np.abs(np.diag(dense[:n, :n], -b)).min() > 0  # the band is really b wide
    factor = _factor(dense, n, b)
    rng = np.random.default_rng(1)
    rhs = rng.normal(size=n + m)
    want = np.linalg.solve(dense, rhs)
    got = factor.solve(rhs)
    assert np.linalg.norm(got - want) <= 1e-9 * np.linalg.norm(want)
    # Several right-hand sides at once (columns).
    many = rng.normal(size=(n + m, 4))
    want_many = np.linalg.solve(dense, many)
    assert np.linalg.norm(factor.solve(many) - want_many) <= 1e-9 * np.linalg.norm(want_many)
    sign, log_det = np.linalg.slogdet(dense)
    assert sign == 1.0
    assert factor.log_det() == pytest.approx(log_det, rel=1e-10, abs=1e-9)


@pytest.mark.parametrize(("n", "b", "m"), CASES)
def test_whitened_products_match_dense_numpy(n, b, m):
    """(G^-1 a)'(G^-1 b) = a' N^-1 b for several columns at once, and G^-1 is lower
    triangular: the first k entries of G^-1 a depend on a's first k entries alone."""
    dense = _bordered_banded(n, b, m, seed=3 * n + b + m)
    factor = _factor(dense, n, b)
    rng = np.random.default_rng(2)
    columns = rng.normal(size=(n + m, 5))
    whitened = factor.whitened(columns)
    want = columns.T @ np.linalg.solve(dense, columns)
    assert np.linalg.norm(whitened.T @ whitened - want) <= 1e-9 * np.linalg.norm(want)
    k = (n + m) // 2
    changed = columns.copy()
    changed[k:] = rng.normal(size=changed[k:].shape)
    np.testing.assert_array_equal(factor.whitened(changed)[:k], whitened[:k])
    np.testing.assert_allclose(factor.whitened(columns[:, 2]), whitened[:, 2], rtol=1e-12, atol=1e-12)


def test_transposed_product_matches_numpy():
    """a'b by the compiled loop equals numpy's, for shapes with a side of one or none; a'a
    exactly symmetric."""
    rng = np.random.default_rng(4)
    for n, k, width in [(50, 7, 8), (1, 3, 1), (20, 1, 5), (0, 2, 3)]:
        a, b = rng.normal(size=(n, k)), rng.normal(size=(n, width))
        np.testing.assert_allclose(transposed_product(a, b), a.T @ b, rtol=1e-12, atol=1e-12)
        np.testing.assert_array_equal(transposed_product(a, a), transposed_product(a, a).T)


@pytest.mark.parametrize(("n", "b", "m"), CASES)
def test_selected_inverse_matches_dense_inverse(n, b, m):
    dense = _bordered_banded(n, b, m, seed=100 + n + 7 * b + 31 * m)
    factor = _factor(dense, n, b, fmt="coo")
    band_inverse = np.linalg.inv(dense[:n, :n])
    full_inverse = np.linalg.inv(dense)
    # The band of B^-1, lower form: z[d, j] = (B^-1)[j + d, j] for j + d < n.
    z = factor.band_of_inverse()
    assert z.shape == (b + 1, n)
    for d in range(b + 1):
        want = np.diag(band_inverse, -d)
        np.testing.assert_allclose(z[d, : n - d], want, rtol=1e-8, atol=1e-12 * np.abs(band_inverse).max())
    # Diagonal blocks of N^-1 at arbitrary starts, for every block size up to b + 1.
    for size in sorted({1, min(2, b + 1), b + 1}):
        starts = np.arange(0, n - size + 1, max(1, (n - size) // 7))
        blocks = factor.diagonal_blocks_of_inverse(starts, size)
        want = np.stack([full_inverse[s : s + size, s : s + size] for s in starts])
        np.testing.assert_allclose(blocks, want, rtol=1e-8, atol=1e-12 * np.abs(full_inverse).max())


@pytest.mark.parametrize(("n", "b", "m"), CASES)
def test_inverse_times_rows_matches_dense_inverse(n, b, m):
    """(N^-1 J')[c, r] at each row's entries, for random sparse rows whose band columns lie
    within b of each other (as the rows of a J with J'J banded), with border columns, and
    padding (column -1) that gets 0."""
    dense = _bordered_banded(n, b, m, seed=200 + n + 7 * b + 31 * m)
    inverse = np.linalg.inv(dense)
    rng = np.random.default_rng(7)
    rows, width = 40, 5
    start = rng.integers(0, max(1, n - b), rows)
    cols = np.where(
        (rng.random((rows, width)) < 0.7) | (m == 0),
        np.minimum(start[:, None] + rng.integers(0, b + 1, (rows, width)), n - 1),
        n + rng.integers(0, max(m, 1), (rows, width)),
    )
    vals = rng.normal(size=(rows, width))
    pad = rng.random((rows, width)) < 0.2
    jac = np.zeros((rows, n + m))
    np.add.at(jac, (np.repeat(np.arange(rows), width), cols.ravel()), np.where(pad, 0.0, vals).ravel())
    want = np.where(pad, 0.0, (inverse @ jac.T)[cols, np.arange(rows)[:, None]])
    cols[pad] = -1
    got = _factor(dense, n, b).inverse_times_rows(cols, vals)
    np.testing.assert_allclose(got, want, rtol=1e-8, atol=1e-10 * np.abs(want).max())
    if b < n - 1:
        far = cols.copy()
        far[0, :2] = [0, b + 1]
        with pytest.raises(ValueError, match="farther apart than the band"):
            _factor(dense, n, b).inverse_times_rows(far, vals)


def test_duplicate_sparse_entries_are_summed_and_upper_band_entries_ignored():
    """The factor reads B from the lower triangle and C from the upper-right block of the
    sparse matrix, summing duplicate (row, col) entries as scipy does."""
    n, b, m = 20, 2, 3
    dense = _bordered_banded(n, b, m, seed=5)
    coo = sparse.coo_matrix(dense)
    half = 0.5 * coo.data
    twice = sparse.coo_matrix(
        (np.concatenate([half, half]), (np.concatenate([coo.row, coo.row]), np.concatenate([coo.col, coo.col]))),
        shape=dense.shape,
    )
    rhs = np.random.default_rng(2).normal(size=n + m)
    got = BorderedBanded(twice, n, b).solve(rhs)
    np.testing.assert_allclose(got, np.linalg.solve(dense, rhs), rtol=1e-9)


def test_a_matrix_wider_than_the_stated_band_is_refused():
    dense = _bordered_banded(15, 3, 2, seed=9)
    with pytest.raises(ValueError, match="not banded"):
        _factor(dense, 15, 2)
