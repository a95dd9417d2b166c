"""The smoothers' O(I J) sums over pairs of particles, for a mixture of Gaussian transitions.

For particles i (log weights log W_i) and points j, with a transition density that is a
mixture of C linear-Gaussian kernels, each whitened so that log f_c(x_j | x_i) = n_c -
|zb_cj - za_ci|^2 / 2 (n_c holding the mixture weight, log|W_c| and the 2 pi term;
`ffbsm.whitened`):

- `backward_weights`: S_i = W_i sum_j V_j f(x_j | x_i) / pred_j, pred_j = sum_k W_k
  f(x_j | x_k), the (unnormalised) smoothed weights of FFBSm (`ffbsm.backward_step`);
- `log_mixture_density`: log sum_c sum_i W_i f_c(x_j | x_i) at points j, the two-filter
  smoother's predictive densities (`rafostrack.smoothing.two_filter`). The squared distance is
  symmetric in i and j, so the same sum runs over a transition's origins or its
  destinations.

The first kernel's terms, log W_i + log f_0(x_j | x_i), are computed for every pair by a
compiled loop (`pair_terms`); their exponentials and sums are numpy's (its exponential is
vectorised, six times faster than a compiled scalar loop's), shifted by each row's maximum.
A further kernel (broad: the drift's jump component) enters row j only where its peak
density, exp(n_c) sum_i W_i, could add more than `MIXTURE_TOL` of the row's sum; elsewhere
its share is below that. Every sum runs in one fixed order, without BLAS: the same bits on
every run, whatever the thread count.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
from numba import njit, prange
from numpy.typing import NDArray

from ..filtering.resampling import log_sum_exp
from ..model.parallel import threaded

MIXTURE_TOL = 1e-4


@njit(cache=True, nogil=True, boundscheck=False)
def pair_terms(za_t, zb, log_norm, log_w, c, rows, terms, top):  # pragma: no cover - compiled
    """top[r] = max_i t_ri and terms[r, i] = t_ri - top[r] (t_ri where top[r] = -inf), with
    t_ri = log W_i + n_c - |zb_c,rows[r] - za_ci|^2 / 2 (za_t (C, d, I): the origins'
    whitened states, dimension-major; zb (C, J, d)), row by row (`_pair_row`)."""
    for r in range(rows.shape[0]):
        _pair_row(r, za_t, zb, log_norm, log_w, c, rows, terms, top)


@njit(cache=True, nogil=True, boundscheck=False, parallel=True)
def pair_terms_threaded(za_t, zb, log_norm, log_w, c, rows, terms, top):  # pragma: no cover - compiled
    """`pair_terms` on numba's threads (`model.parallel`)."""
    for r in prange(rows.shape[0]):
        _pair_row(np.intp(r), za_t, zb, log_norm, log_w, c, rows, terms, top)


@njit(cache=True, nogil=True, boundscheck=False, inline="always")
def _pair_row(r, za_t, zb, log_norm, log_w, c, rows, terms, top):  # pragma: no cover - compiled
    """Row r of `pair_terms`. Loops that the compiler vectorises: the squared distance one
    dimension at a time, the maximum over eight lanes."""
    d, n_i = za_t.shape[1], za_t.shape[2]
    whole = n_i - n_i % 8
    lanes = np.empty(8)
    j = rows[r]
    row = terms[r]
    for i in range(n_i):
        row[i] = 0.0
    for e in range(d):
        target = zb[c, j, e]
        origin = za_t[c, e]
        for i in range(n_i):
            diff = target - origin[i]
            row[i] += diff * diff
    base = log_norm[c]
    for i in range(n_i):
        row[i] = log_w[i] + base - 0.5 * row[i]
    for k in range(8):
        lanes[k] = -np.inf
    for i in range(0, whole, 8):
        for k in range(8):
            if row[i + k] > lanes[k]:
                lanes[k] = row[i + k]
    best = -np.inf
    for k in range(8):
        best = max(best, lanes[k])
    for i in range(whole, n_i):
        best = max(best, row[i])
    top[r] = best
    if best > -np.inf:
        for i in range(n_i):
            row[i] -= best


# Rows per block: a block of terms (BLOCK x 512 doubles, 0.5 MB) stays in the cache between
# the compiled loop that fills it and numpy's exponential and sum.
BLOCK = 128
# Pair terms that count as one of `model.parallel.threaded`'s items (a block of BLOCK rows
# of 512 columns: 256 items).
PAIRS_PER_ITEM = 256


def _shifted_exp(
    za_t: NDArray,
    zb: NDArray,
    log_norm: NDArray,
    log_w: NDArray,
    c: int,
    rows: NDArray[np.intp],
    terms: NDArray,
    top: NDArray,
) -> NDArray[np.float64]:
    """terms <- exp(t_ri - top_r) of kernel c over `rows`, top <- top_r (`pair_terms`);
    returns the row sums."""
    kernel = pair_terms_threaded if threaded(len(rows) * za_t.shape[2] // PAIRS_PER_ITEM) else pair_terms
    kernel(za_t, zb, log_norm, log_w, c, rows, terms, top)
    np.exp(terms, out=terms)
    return terms.sum(axis=1)


def _blocks(
    za_t: NDArray, zb: NDArray, log_norm: NDArray, log_w: NDArray, c: int, rows: NDArray[np.intp]
) -> Iterator[tuple[slice, NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]]:
    """Kernel c's terms over `rows`, `BLOCK` rows at a time: (the block's slice of `rows`,
    exp(t_ri - top_r), top_r, the row sums). The arrays are reused from block to block."""
    terms = np.empty((min(BLOCK, len(rows)), za_t.shape[2]))
    top = np.empty(len(terms))
    for start in range(0, len(rows), BLOCK):
        n = min(BLOCK, len(rows) - start)
        block = slice(start, start + n)
        sums = _shifted_exp(za_t, zb, log_norm, log_w, c, rows[block], terms[:n], top[:n])
        yield block, terms[:n], top[:n], sums


def _log(x: NDArray) -> NDArray[np.float64]:
    with np.errstate(divide="ignore"):
        return np.log(x)


def _reaches(log_norm: NDArray, log_mass: float, log_sum: NDArray) -> list[NDArray[np.bool_]]:
    """Per further kernel c >= 1, the rows (of first-kernel log sums `log_sum`) where its
    peak exp(n_c) sum_i W_i could add more than MIXTURE_TOL."""
    return [log_norm[c] + log_mass - log_sum >= math.log(MIXTURE_TOL) for c in range(1, len(log_norm))]


def log_mixture_density(za: NDArray, zb: NDArray, log_norm: NDArray, log_w: NDArray) -> NDArray[np.float64]:
    """(J,) log sum_c sum_i exp(log W_i + n_c - |zb_cj - za_ci|^2 / 2) (module docstring), for
    za (C, I, d), zb (C, J, d), log_norm (C,), log_w (I,)."""
    za_t = np.ascontiguousarray(za.transpose(0, 2, 1))
    total = np.empty(zb.shape[1])
    for block, _, top, sums in _blocks(za_t, zb, log_norm, log_w, 0, np.arange(len(total))):
        total[block] = top + _log(sums)
    for c, reached in enumerate(_reaches(log_norm, log_sum_exp(log_w), total), 1):
        rows = np.flatnonzero(reached)
        for block, _, top, sums in _blocks(za_t, zb, log_norm, log_w, c, rows):
            total[rows[block]] = np.logaddexp(total[rows[block]], top + _log(sums))
    return total


def backward_weights(za: NDArray, zb: NDArray, log_norm: NDArray, log_w: NDArray, v: NDArray) -> NDArray[np.float64]:
    """(I,) S_i = W_i sum_j V_j f(x_j | x_i) / pred_j (module docstring), for za (C, I, d),
    zb (C, J, d), log_norm (C,), log_w (I,), v (J,)."""
    za_t = np.ascontiguousarray(za.transpose(0, 2, 1))
    log_mass = log_sum_exp(log_w)
    out = np.zeros(za.shape[1])
    for block, terms, top, sums in _blocks(za_t, zb, log_norm, log_w, 0, np.arange(zb.shape[1])):
        for c, reached in enumerate(_reaches(log_norm, log_mass, top + _log(sums)), 1):
            # Rows the kernel's share reaches: its terms added in, both scaled to the larger top.
            rows = np.flatnonzero(reached)
            if len(rows) == 0:
                continue
            more, more_top = np.empty((len(rows), terms.shape[1])), np.empty(len(rows))
            _shifted_exp(za_t, zb, log_norm, log_w, c, block.start + rows, more, more_top)
            shift = np.maximum(top[rows], more_top)
            shift = np.where(np.isfinite(shift), shift, 0.0)
            terms[rows] = terms[rows] * np.exp(top[rows] - shift)[:, None] + more * np.exp(more_top - shift)[:, None]
            top[rows] = shift
            sums[rows] = terms[rows].sum(axis=1)
        scale = np.divide(v[block], sums, out=np.zeros_like(sums), where=sums > 0)
        out += np.einsum("j,ji->i", scale, terms)
    return out
