"""Symmetric positive-definite systems that are banded but for a dense border (arrowhead).

The normal matrix of a state-space smoother with static parameters orders its unknowns by
time, a few per node, then the static ones: consecutive nodes couple, every node couples
with the statics. With the banded block B (bandwidth b), the border C (n x m) and the
corner E (m x m),

    N = [[B, C], [C', E]],   S = E - C' B^-1 C  (the Schur complement),
    log|N| = log|B| + log|S|,

solves and log-determinants cost O(n b^2 + n b m + m^3) (LAPACK's banded Cholesky), and
the diagonal blocks of N^-1 come from the band of B^-1 by the Takahashi recursion: with
B = U' D U (U unit upper banded), Z = B^-1 satisfies, for i <= j <= i + b,

    Z_ij = delta_ij / D_i - sum_{k=i+1}^{i+b} U_ik Z_kj,

computed from the last row up, then [N^-1]_xx = Z + Y S^-1 Y' with Y = B^-1 C, [N^-1]_xs =
-Y S^-1 and [N^-1]_ss = S^-1: the entries of N^-1 that pair unknowns coupled in N.
"""

from __future__ import annotations

import functools

import numpy as np
from numba import njit
from numpy.typing import NDArray
from scipy import sparse
from scipy.linalg import cho_factor, cho_solve, cho_solve_banded, cholesky_banded, solve_triangular
from scipy.linalg.lapack import dtbtrs


class BorderedBanded:
    """Factorisation of N = [[B, C], [C', E]] (module docstring) from the sparse N, whose
    first `n_band` unknowns form the band of half-width `bandwidth`."""

    def __init__(self, normal: sparse.spmatrix, n_band: int, bandwidth: int):
        normal = sparse.csr_matrix(normal)
        normal.sum_duplicates()  # one entry per (row, column), each placed below (free when so already)
        coo = normal.tocoo()
        r, c, v = coo.row, coo.col, coo.data
        self.n, self.b = n_band, bandwidth
        m = normal.shape[0] - n_band
        band = np.zeros((bandwidth + 1, n_band))  # lower form: band[d, j] = B[j + d, j]
        inside = (r < n_band) & (c < n_band) & (r >= c)
        if np.any(r[inside] - c[inside] > bandwidth):
            raise ValueError(f"the matrix is not banded with half-width {bandwidth}")
        band[r[inside] - c[inside], c[inside]] = v[inside]
        self.border = np.zeros((n_band, m))
        edge = (r < n_band) & (c >= n_band)
        self.border[r[edge], c[edge] - n_band] = v[edge]
        corner = np.zeros((m, m))
        low = (r >= n_band) & (c >= n_band)
        corner[r[low] - n_band, c[low] - n_band] = v[low]
        self.chol = cholesky_banded(band, lower=True)
        # C' B^-1 C = H'H with H = L^-1 C (B = L L'): one triangular solve per column, not two.
        half, info = dtbtrs(self.chol, self.border, uplo="L") if m else (self.border, 0)
        if info != 0:
            raise np.linalg.LinAlgError(f"banded triangular solve failed (LAPACK info {info})")
        self.half = half
        # Dense products by einsum, not BLAS: the same bits whatever the thread count.
        schur = corner - np.einsum("nk,nl->kl", half, half)
        self.schur = cho_factor(schur, lower=True) if m else (np.zeros((0, 0)), True)

    def log_det(self) -> float:
        return float(2.0 * np.sum(np.log(self.chol[0])) + 2.0 * np.sum(np.log(np.diag(self.schur[0]))))

    def schur_solve(self, rhs: NDArray) -> NDArray[np.float64]:
        """S^-1 rhs."""
        return cho_solve(self.schur, rhs) if len(rhs) else np.zeros_like(rhs)

    def whitened(self, rhs: NDArray) -> NDArray[np.float64]:
        """G^-1 rhs, where N = G G' with G = [[L, 0], [H', M]] (B = L L', H = L^-1 C, S = M M'):
        for a product a' N^-1 b = (G^-1 a)'(G^-1 b), one triangular solve against `solve`'s two
        Cholesky solves (the band's by `_forward_substituted`, every column in one pass)."""
        rhs = np.asarray(rhs, dtype=float)
        columns = rhs.reshape(len(rhs), -1)
        top = _forward_substituted(self.chol, np.ascontiguousarray(columns[: self.n]))
        bottom = columns[self.n :] - transposed_product(np.ascontiguousarray(self.half), top)
        if len(bottom):
            bottom = solve_triangular(self.schur[0], bottom, lower=True)
        return np.concatenate([top, bottom]).reshape(rhs.shape)

    def solve(self, rhs: NDArray) -> NDArray[np.float64]:
        """N^-1 rhs (block elimination)."""
        top, bottom = rhs[: self.n], rhs[self.n :]
        b_top = cho_solve_banded((self.chol, True), top)
        x_bottom = self.schur_solve(bottom - np.einsum("nk,n...->k...", self.border, b_top))
        x_top = cho_solve_banded((self.chol, True), top - np.einsum("nk,k...->n...", self.border, x_bottom))
        return np.concatenate([x_top, x_bottom])

    @functools.cached_property
    def y(self) -> NDArray[np.float64]:
        """B^-1 C = L'^-1 H (for the diagonal blocks of N^-1)."""
        if self.half.shape[1] == 0:
            return self.half
        y, info = dtbtrs(self.chol, self.half, uplo="L", trans="T")
        if info != 0:
            raise np.linalg.LinAlgError(f"banded triangular solve failed (LAPACK info {info})")
        return y

    def band_of_inverse(self) -> NDArray[np.float64]:
        """The band of B^-1, in the lower form of `cholesky_banded` (Takahashi recursion)."""
        return _takahashi(self.chol)

    @functools.cached_property
    def inverse_parts(self) -> tuple[NDArray, NDArray, NDArray]:
        """N^-1 in parts: the band of [N^-1]_xx = Z + Y S^-1 Y' (lower form), the border
        block [N^-1]_xs = -Y S^-1 and the corner [N^-1]_ss = S^-1."""
        n, b, m = self.n, self.b, self.y.shape[1]
        band = self.band_of_inverse()
        if m == 0:
            return band, np.zeros((n, 0)), np.zeros((0, 0))
        y_s_inv = self.schur_solve(self.y.T).T
        for d in range(b + 1):
            band[d, : n - d] += np.einsum("nk,nk->n", self.y[d:], y_s_inv[: n - d])
        return band, -y_s_inv, self.schur_solve(np.eye(m))

    def inverse_times_rows(self, cols: NDArray[np.intp], vals: NDArray) -> NDArray[np.float64]:
        """(N^-1 J')[cols[r, a], r] for the sparse rows r of J with entries (cols, vals), each
        (R, e), from `inverse_parts`; a column -1 pads a row to the width e (its entry is
        left out, and gets 0). Every pair of one row's columns must lie within the band or
        touch the border, as in the rows of a J whose J'J is N."""
        return _inverse_times_rows(cols, np.asarray(vals, dtype=float), *self.inverse_parts, self.n)

    def diagonal_blocks_of_inverse(self, starts: NDArray[np.intp], size: int) -> NDArray[np.float64]:
        """(len(starts), size, size) diagonal blocks of N^-1 at the band's unknowns
        starts[k] .. starts[k] + size - 1 (size <= bandwidth + 1)."""
        band = self.inverse_parts[0]
        out = np.empty((len(starts), size, size))
        for p in range(size):
            for q in range(size):
                out[:, p, q] = band[abs(p - q), starts + min(p, q)]
        return out


@njit(cache=True, nogil=True)
def _takahashi(chol: NDArray) -> NDArray:  # pragma: no cover - compiled
    """The band of B^-1 from B's lower banded Cholesky factor (module docstring): z[d, i] =
    Z_{i+d, i}, from the last row up."""
    b, n = chol.shape[0] - 1, chol.shape[1]
    z = np.zeros((b + 1, n))
    for i in range(n - 1, -1, -1):
        width = min(b, n - 1 - i)
        diag = chol[0, i]
        # Z_{i, i+e} = -sum_d U_{i, i+d} Z_{i+d, i+e}, U_{i, i+d} = L_{i+d, i} / L_ii.
        for e in range(1, width + 1):
            acc = 0.0
            for d in range(1, width + 1):
                k, j = i + d, i + e
                acc += chol[d, i] / diag * (z[k - j, j] if k >= j else z[j - k, k])
            z[e, i] = -acc
        acc = 0.0
        for d in range(1, width + 1):
            acc += chol[d, i] / diag * z[d, i]
        z[0, i] = 1.0 / (diag * diag) - acc
    return z


@njit(cache=True, nogil=True)
def _inverse_times_rows(cols, vals, band, border, corner, n):  # pragma: no cover - compiled
    """`BorderedBanded.inverse_times_rows` from the band, border and corner of N^-1."""
    rows, width = cols.shape
    bandwidth = band.shape[0] - 1
    out = np.zeros((rows, width))
    for r in range(rows):
        for a in range(width):
            i = cols[r, a]
            if i < 0:
                continue
            acc = 0.0
            for c in range(width):
                j, v = cols[r, c], vals[r, c]
                if j < 0:
                    continue
                if i < n and j < n:
                    d = abs(i - j)
                    if d > bandwidth:
                        raise ValueError("a row's columns lie farther apart than the band")
                    acc += band[d, min(i, j)] * v
                elif i < n:
                    acc += border[i, j - n] * v
                elif j < n:
                    acc += border[j, i - n] * v
                else:
                    acc += corner[i - n, j - n] * v
            out[r, a] = acc
    return out


@njit(cache=True, nogil=True)
def _forward_substituted(chol: NDArray, rhs: NDArray) -> NDArray:  # pragma: no cover - compiled
    """L^-1 rhs (rhs (n, k)) for the lower banded Cholesky factor L of `cholesky_banded`
    (chol[d, j] = L_{j+d, j}): x_i = (rhs_i - sum_{d=1}^{b} L_{i, i-d} x_{i-d}) / L_ii, row
    by row, all k columns at once (LAPACK's dtbtrs solves them one at a time)."""
    b, n = chol.shape[0] - 1, chol.shape[1]
    x = rhs.copy()
    for i in range(n):
        for d in range(min(b, i), 0, -1):
            factor = chol[d, i - d]
            for c in range(x.shape[1]):
                x[i, c] -= factor * x[i - d, c]
        for c in range(x.shape[1]):
            x[i, c] /= chol[0, i]
    return x


@njit(cache=True, nogil=True)
def transposed_product(a: NDArray, b: NDArray) -> NDArray:  # pragma: no cover - compiled
    """a' b for a (n, k) and b (n, l), summed over n in order: a dense product with the same
    bits whatever the machine's BLAS threads (as einsum's), in about 0.6 of einsum's time."""
    out = np.zeros((a.shape[1], b.shape[1]))
    for n in range(a.shape[0]):
        for k in range(a.shape[1]):
            factor = a[n, k]
            for col in range(b.shape[1]):
                out[k, col] += factor * b[n, col]
    return out
