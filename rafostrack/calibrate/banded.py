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

computed from the last row up, then [N^-1]_xx = Z + Y S^-1 Y' with Y = B^-1 C.
"""

from __future__ import annotations

import functools

import numpy as np
from numpy.typing import NDArray
from scipy import sparse
from scipy.linalg import cho_factor, cho_solve, cho_solve_banded, cholesky_banded
from scipy.linalg.lapack import dtbtrs


class BorderedBanded:
    """Factorisation of N = [[B, C], [C', E]] (module docstring) from the sparse N, whose
    first `n_band` unknowns form the band of half-width `bandwidth`."""

    def __init__(self, normal: sparse.spmatrix, n_band: int, bandwidth: int):
        coo = sparse.coo_matrix(normal)
        r, c, v = coo.row, coo.col, coo.data
        self.n, self.b = n_band, bandwidth
        m = normal.shape[0] - n_band
        band = np.zeros((bandwidth + 1, n_band))  # lower form: band[d, j] = B[j + d, j]
        inside = (r < n_band) & (c < n_band) & (r >= c)
        if np.any(r[inside] - c[inside] > bandwidth):
            raise ValueError(f"the matrix is not banded with half-width {bandwidth}")
        np.add.at(band, (r[inside] - c[inside], c[inside]), v[inside])
        self.border = np.zeros((n_band, m))
        edge = (r < n_band) & (c >= n_band)
        np.add.at(self.border, (r[edge], c[edge] - n_band), v[edge])
        corner = np.zeros((m, m))
        low = (r >= n_band) & (c >= n_band)
        np.add.at(corner, (r[low] - n_band, c[low] - n_band), v[low])
        self.chol = cholesky_banded(band, lower=True)
        # C' B^-1 C = H'H with H = L^-1 C (B = L L'): one triangular solve per column, not two.
        half, info = dtbtrs(self.chol, self.border, uplo="L") if m else (self.border, 0)
        if info != 0:
            raise np.linalg.LinAlgError(f"banded triangular solve failed (LAPACK info {info})")
        # Dense products by einsum, not BLAS: the same bits whatever the thread count.
        schur = corner - np.einsum("nk,nl->kl", half, half)
        self.schur = cho_factor(schur, lower=True) if m else (np.zeros((0, 0)), True)

    def log_det(self) -> float:
        return float(2.0 * np.sum(np.log(self.chol[0])) + 2.0 * np.sum(np.log(np.diag(self.schur[0]))))

    def _schur_solve(self, rhs: NDArray) -> NDArray[np.float64]:
        return cho_solve(self.schur, rhs) if len(rhs) else np.zeros_like(rhs)

    def solve(self, rhs: NDArray) -> NDArray[np.float64]:
        """N^-1 rhs (block elimination)."""
        top, bottom = rhs[: self.n], rhs[self.n :]
        b_top = cho_solve_banded((self.chol, True), top)
        x_bottom = self._schur_solve(bottom - np.einsum("nk,n...->k...", self.border, b_top))
        x_top = cho_solve_banded((self.chol, True), top - np.einsum("nk,k...->n...", self.border, x_bottom))
        return np.concatenate([x_top, x_bottom])

    @functools.cached_property
    def y(self) -> NDArray[np.float64]:
        """B^-1 C (for the diagonal blocks of N^-1)."""
        return cho_solve_banded((self.chol, True), self.border)

    def band_of_inverse(self) -> NDArray[np.float64]:
        """The band of B^-1, in the lower form of `cholesky_banded` (Takahashi recursion)."""
        n, b, chol = self.n, self.b, self.chol
        diag = chol[0]
        # U_ik for k = i+1..i+b: L_ki / L_ii, with L_ki = chol[k - i, i].
        u = chol[1:] / diag[None, :]  # (b, n): u[d - 1, i] = U_{i, i+d}
        z = np.zeros((b + 1, n))  # z[d, i] = Z_{i+d, i} = Z_{i, i+d}
        for i in range(n - 1, -1, -1):
            width = min(b, n - 1 - i)
            ui = u[:width, i]
            if width:
                # Z_{k, j} for k, j in i+1..i+width from the band (|k - j| <= b holds).
                block = np.empty((width, width))
                for d in range(width):
                    block[d, d:] = z[: width - d, i + 1 + d]
                    block[d:, d] = z[: width - d, i + 1 + d]
                row = -np.einsum("de,d->e", block, ui)  # Z_{i, j} for j = i+1..i+width
                z[1 : width + 1, i] = row
                z[0, i] = 1.0 / diag[i] ** 2 - np.einsum("d,d->", ui, row)
            else:
                z[0, i] = 1.0 / diag[i] ** 2
        return z

    def diagonal_blocks_of_inverse(self, starts: NDArray[np.intp], size: int) -> NDArray[np.float64]:
        """(len(starts), size, size) diagonal blocks of N^-1 at the band's unknowns
        starts[k] .. starts[k] + size - 1 (size <= bandwidth + 1)."""
        z = self.band_of_inverse()
        out = np.empty((len(starts), size, size))
        for p in range(size):
            for q in range(size):
                d = abs(p - q)
                out[:, p, q] = z[d, starts + min(p, q)]
        if self.y.shape[1] == 0:
            return out
        yb = self.y[starts[:, None] + np.arange(size)]  # (k, size, m)
        s_inv_yt = self._schur_solve(yb.reshape(-1, yb.shape[-1]).T).T.reshape(yb.shape)
        return out + np.einsum("kpm,kqm->kpq", yb, s_inv_yt)
