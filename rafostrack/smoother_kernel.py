"""The smoother's backward step as a compiled kernel (`smoother.backward_step`).

For filter particles i at t (log weights log W_i) and particles j at t + 1 (weights V_j,
summing to 1), with a transition density that is a mixture of C linear-Gaussian kernels,
each whitened so that log f_c(x_j | x_i) = n_c - |zb_cj - za_ci|^2 / 2 (n_c holding the
mixture weight, log|W_c| and the 2 pi term), the kernel returns

    S_i = W_i sum_j V_j f(x_j | x_i) / pred_j,    pred_j = sum_k W_k f(x_j | x_k),

the (unnormalised) smoothed weights of FFBSm. One row j at a time: the first kernel's row
terms r_i = log W_i + n_0 - |zb_0j - za_0i|^2 / 2, their maximum, log pred_j by a shifted
sum. A further kernel (broad: a jump component) enters row j only where its peak density
exp(n_c) could add more than `MIXTURE_TOL` of pred_j; elsewhere its share is below that
(module `smoother`). Then S_i += V_j exp(r_i - log pred_j). Every sum runs in one fixed
order: the same bits on every run.

`log_mixture_density` evaluates such a mixture itself, log sum_c sum_i W_i f_c(x_j | x_i) at
points x_j (the two-filter smoother's predictive densities, `rafostrack.two_filter`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

MIXTURE_TOL = 1e-4
# exp(-48) < 1e-20: terms this far below a row's largest are left out of its sums.
NEGLIGIBLE = -48.0


@njit(cache=True, nogil=True, boundscheck=False)
def _row(za, zb, log_norm, log_w, c, j, row):  # pragma: no cover - compiled
    """row_i = log W_i + log f_c(x_j | x_i); returns the row's maximum."""
    n_i, d = za.shape[1], za.shape[2]
    top = -np.inf
    for i in range(n_i):
        q = 0.0
        for e in range(d):
            diff = zb[c, j, e] - za[c, i, e]
            q += diff * diff
        r = log_w[i] + log_norm[c] - 0.5 * q
        row[i] = r
        if r > top:
            top = r
    return top


@njit(cache=True, nogil=True, boundscheck=False)
def _exp_shifted(row, top):  # pragma: no cover - compiled
    """row_i <- exp(row_i - top), zero where row_i - top <= NEGLIGIBLE (a share below 1e-20
    of the row's sum: beyond float64 resolution); returns the sum."""
    total = 0.0
    for i in range(row.shape[0]):
        shifted = row[i] - top
        row[i] = math.exp(shifted) if shifted > NEGLIGIBLE else 0.0
        total += row[i]
    return total


@njit(cache=True, nogil=True, boundscheck=False)
def backward_kernel(za, zb, log_norm, log_w, v, out):  # pragma: no cover - compiled
    """za (C, I, d), zb (C, J, d), log_norm (C,), log_w (I,), v (J,) -> out (I,) (module
    docstring)."""
    n_comp, n_i = za.shape[0], za.shape[1]
    n_j = zb.shape[1]
    row = np.empty(n_i)
    extra = np.empty(n_i)
    for i in range(n_i):
        out[i] = 0.0
    for j in range(n_j):
        top = _row(za, zb, log_norm, log_w, 0, j, row)
        if top == -np.inf:
            continue
        log_pred = top + math.log(_exp_shifted(row, top))
        mixed = False
        for c in range(1, n_comp):
            mixed = mixed or log_norm[c] - log_pred >= math.log(MIXTURE_TOL)
        if mixed:
            # Back to log terms, every component log-added in (rare: the jump's share matters).
            _row(za, zb, log_norm, log_w, 0, j, row)
            for c in range(1, n_comp):
                _row(za, zb, log_norm, log_w, c, j, extra)
                for i in range(n_i):
                    a, b = row[i], extra[i]
                    big = max(a, b)
                    row[i] = big + math.log1p(math.exp(-abs(a - b))) if big > -np.inf else big
            top = -np.inf
            for i in range(n_i):
                top = max(top, row[i])
            _exp_shifted(row, top)
        total = 0.0
        for i in range(n_i):
            total += row[i]
        scale = v[j] / total
        for i in range(n_i):
            out[i] += scale * row[i]


@njit(cache=True, nogil=True, boundscheck=False)
def log_mixture_density(za, zb, log_norm, log_w, out):  # pragma: no cover - compiled
    """out_j = log sum_c sum_i exp(log W_i + n_c - |zb_cj - za_ci|^2 / 2): the log density at
    points j of the weighted mixture of kernels about points i (za (C, I, d), zb (C, J, d),
    log_norm (C,), log_w (I,) -> out (J,)). The squared distance is symmetric in i and j,
    so the same kernel sums over a transition's origins or over its destinations."""
    n_comp, n_i = za.shape[0], za.shape[1]
    rows = np.empty((n_comp, n_i))
    for j in range(zb.shape[1]):
        top = -np.inf
        for c in range(n_comp):
            top = max(top, _row(za, zb, log_norm, log_w, c, j, rows[c]))
        if top == -np.inf:
            out[j] = -np.inf
            continue
        total = 0.0
        for c in range(n_comp):
            total += _exp_shifted(rows[c], top)
        out[j] = top + math.log(total)
