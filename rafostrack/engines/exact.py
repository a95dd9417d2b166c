"""Exact association sum and marginals by dynamic programming over subsets of signals.

Beacons are added one at a time; the state is the set (bitmask) of signals already
matched. Forward: F_i(m) = weight of all ways beacons 1..i cover exactly m,
    F_i(m) = u_i F_{i-1}(m) + sum_{j in m} w_ij F_{i-1}(m - {j}),
and backward: B_i(m) = weight of all completions by beacons i+1..s when m is taken,
    B_{i-1}(m) = u_i B_i(m) + sum_{j not in m} w_ij B_i(m + {j}),   B_s(m) = 1
(unmatched signals are clutter, weight 1 after the model's normalisation). Then
    Z = sum_m F_s(m),  P(i <-> j) = sum_{m not containing j} F_{i-1}(m) w_ij B_i(m + {j}) / Z.
Cost O(s r 2^r) per particle. Arithmetic is linear but scaled: each beacon's factors are
divided by u_i (so the "unmatched" option weighs 1 and no table entry can shrink), and each
table is renormalised to a maximum of 1 with its log-scale kept aside. Marginals are
assembled in log space. Accurate (1e-9 relative, tests/test_engines.py) for log(w_ij/u_i)
within +-300; realistic windows stay within +-40.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError
from . import Association

MAX_SIGNALS = 12
# Particles per chunk, so that the tables (s+1, chunk, 2^K) stay within ~64 MB.
_TABLE_BUDGET = 8_000_000


def _transitions(k: int) -> list[tuple[NDArray[np.intp], NDArray[np.intp]]]:
    """For each signal j: the masks without bit j and the same masks with it."""
    masks = np.arange(1 << k)
    out = []
    for j in range(k):
        without = masks[(masks >> j) & 1 == 0]
        out.append((without, without | (1 << j)))
    return out


def associate(log_match: NDArray, log_unheard: NDArray) -> Association:
    """Exact log Z and pair marginals (see module docstring); refuses K > 12."""
    n, s, k = log_match.shape
    if k > MAX_SIGNALS:
        raise InputError(
            f"the exact method handles at most {MAX_SIGNALS} stored signals per window "
            f"(cost grows as 2^r); this window has {k}: use --method bp"
        )
    log_u_total = log_unheard.sum(axis=1)
    if k == 0 or s == 0:
        return Association(log_u_total, np.zeros((n, s, k)))
    chunk = max(1, _TABLE_BUDGET // ((s + 1) << k))
    log_z = np.empty(n)
    p_match = np.empty((n, s, k))
    for lo in range(0, n, chunk):
        sl = slice(lo, min(n, lo + chunk))
        log_z[sl], p_match[sl] = _associate_chunk(log_match[sl] - log_unheard[sl, :, None], k)
    return Association(log_z + log_u_total, p_match)


def _associate_chunk(log_w: NDArray, k: int) -> tuple[NDArray, NDArray]:
    n, s, _ = log_w.shape
    w = np.exp(log_w)  # w_ij / u_i
    moves = _transitions(k)
    n_masks = 1 << k

    fwd = np.zeros((s + 1, n, n_masks))
    fwd_log = np.zeros((s + 1, n))
    fwd[0, :, 0] = 1.0
    for i in range(s):
        cur, nxt = fwd[i], fwd[i + 1]
        nxt[:] = cur
        for j, (without, with_j) in enumerate(moves):
            nxt[:, with_j] += cur[:, without] * w[:, i, j, None]
        scale = nxt.max(axis=1)  # >= max of cur = 1: the unmatched option weighs 1
        nxt /= scale[:, None]
        fwd_log[i + 1] = fwd_log[i] + np.log(scale)

    bwd = np.ones((s + 1, n, n_masks))
    bwd_log = np.zeros((s + 1, n))
    for i in range(s - 1, -1, -1):
        cur, prv = bwd[i + 1], bwd[i]
        prv[:] = cur
        for j, (without, with_j) in enumerate(moves):
            prv[:, without] += cur[:, with_j] * w[:, i, j, None]
        scale = prv.max(axis=1)
        prv /= scale[:, None]
        bwd_log[i] = bwd_log[i + 1] + np.log(scale)

    log_z = fwd_log[s] + np.log(fwd[s].sum(axis=1))
    p_match = np.empty((n, s, k))
    with np.errstate(divide="ignore"):  # a pair no matching uses has probability exactly 0
        for i in range(s):
            log_rel = fwd_log[i] + bwd_log[i + 1] - log_z
            for j, (without, with_j) in enumerate(moves):
                pair = np.einsum("pm,pm->p", fwd[i][:, without], bwd[i + 1][:, with_j])
                p_match[:, i, j] = np.exp(np.log(pair) + log_w[:, i, j] + log_rel)
    return log_z, p_match
