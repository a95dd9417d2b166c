"""Exact association sum and marginals by dynamic programming over subsets of signals.

Beacons are added one at a time; the state is the set (bitmask) of signals already
matched. Forward: F_i(m) = weight of all ways beacons 1..i cover exactly m,
    F_i(m) = u_i F_{i-1}(m) + sum_{j in m} w_ij F_{i-1}(m - {j}),
and backward: B_i(m) = weight of all completions by beacons i+1..s when m is taken,
    B_{i-1}(m) = u_i B_i(m) + sum_{j not in m} w_ij B_i(m + {j}),   B_s(m) = 1
(unmatched signals are clutter, weight 1 after the model's normalisation). Then
    Z = sum_m F_s(m),  P(i <-> j) = sum_{m not containing j} F_{i-1}(m) w_ij B_i(m + {j}) / Z.
Echo pairs (`model.echo_factors`): a beacon may also take two signals j < j' at once,
    F_i(m) += w_ij E_jj' F_{i-1}(m - {j, j'}),   B_{i-1}(m) += w_ij E_jj' B_i(m + {j, j'}),
and such a pair counts towards both signals' marginals.
Cost O(s r 2^r) per particle (O(s r^2 2^r) with echoes). Arithmetic is linear but scaled:
each beacon's factors are divided by u_i (so the "unmatched" option weighs 1 and no table
entry can shrink), and each table is renormalised to a maximum of 1 with its log-scale kept aside. Marginals are
assembled in log space. Accurate (1e-9 relative, tests/test_engines.py) for log(w_ij/u_i)
within +-300; realistic windows stay within +-40.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..config import Config
from ..errors import InputError
from .base import Association, Engine

MAX_SIGNALS = 12
# Particles per chunk, so that the tables (s+1, chunk, 2^K) stay within ~64 MB.
_TABLE_BUDGET = 8_000_000


def _split(table: NDArray, j: int, k: int) -> tuple[NDArray, NDArray]:
    """Views of a (2^k, P) table on the masks without and with bit j (no copies)."""
    view = table.reshape(1 << (k - 1 - j), 2, 1 << j, table.shape[-1])
    return view[:, 0], view[:, 1]


def associate(
    log_match: NDArray, log_unheard: NDArray, *, marginals: bool = True, log_echo: NDArray | None = None
) -> Association:
    """Exact log Z and pair marginals (see module docstring); refuses K > 12.

    `log_echo` (K, K): the echo pair terms log E_jj' (`model.echo_factors`); a beacon may
    then take a pair j < j' with weight w_ij E_jj', and both signals are its own.
    `marginals=False` runs the forward pass only (a third of the cost) and returns NaN
    marginals.
    """
    n, s, k = log_match.shape
    if k > MAX_SIGNALS:
        raise InputError(
            f"the exact method handles at most {MAX_SIGNALS} stored signals per window "
            f"(cost grows as 2^r); this window has {k}: use --engine bp"
        )
    log_u_total = log_unheard.sum(axis=1)
    if k == 0 or s == 0:
        return Association(log_u_total, np.zeros((n, s, k)))
    pairs = _pairs(log_echo, k)
    chunk = max(1, _TABLE_BUDGET // ((s + 1) << k))
    log_z = np.empty(n)
    p_match = np.empty((n, s, k))
    p_echo = np.zeros((n, s, k))
    for lo in range(0, n, chunk):
        sl = slice(lo, min(n, lo + chunk))
        log_z[sl], p_match[sl], p_echo[sl] = _associate_chunk(
            log_match[sl] - log_unheard[sl, :, None], k, marginals, pairs
        )
    return Association(log_z + log_u_total, p_match, p_echo if pairs else None)


def _pairs(log_echo: NDArray | None, k: int) -> list[tuple[int, int, float, NDArray, NDArray]]:
    """Echo pairs (j, j', E_jj', masks holding neither, the same masks with both) with E > 0."""
    if log_echo is None:
        return []
    masks = np.arange(1 << k)
    out = []
    for j in range(k):
        for jj in range(j + 1, k):
            if np.isfinite(log_echo[j, jj]):
                both = (1 << j) | (1 << jj)
                without = masks[(masks & both) == 0]
                out.append((j, jj, float(np.exp(log_echo[j, jj])), without, without | both))
    return out


def _associate_chunk(
    log_w: NDArray, k: int, marginals: bool, pairs: list[tuple[int, int, float, NDArray, NDArray]]
) -> tuple[NDArray, NDArray, NDArray]:
    # Tables are (masks, particles): particles on the contiguous axis.
    n, s, _ = log_w.shape
    w = np.exp(np.moveaxis(log_w, 0, -1))  # (s, K, P): w_ij / u_i
    n_masks = 1 << k

    fwd = np.zeros((s + 1, n_masks, n))
    fwd_log = np.zeros((s + 1, n))
    fwd[0, 0] = 1.0
    for i in range(s):
        nxt = fwd[i + 1]
        nxt[:] = fwd[i]
        for j in range(k):
            _split(nxt, j, k)[1][...] += _split(fwd[i], j, k)[0] * w[i, j]
        for j, _, echo, without, both in pairs:
            nxt[both] += fwd[i][without] * (w[i, j] * echo)
        scale = nxt.max(axis=0)  # >= max of the previous table = 1: the unmatched option weighs 1
        nxt /= scale
        fwd_log[i + 1] = fwd_log[i] + np.log(scale)
    log_z = fwd_log[s] + np.log(fwd[s].sum(axis=0))
    if not marginals:
        return log_z, np.full((n, s, k), np.nan), np.full((n, s, k), np.nan)

    bwd = np.ones((s + 1, n_masks, n))
    bwd_log = np.zeros((s + 1, n))
    for i in range(s - 1, -1, -1):
        prv = bwd[i]
        prv[:] = bwd[i + 1]
        for j in range(k):
            _split(prv, j, k)[0][...] += _split(bwd[i + 1], j, k)[1] * w[i, j]
        for j, _, echo, without, both in pairs:
            prv[without] += bwd[i + 1][both] * (w[i, j] * echo)
        scale = prv.max(axis=0)
        prv /= scale
        bwd_log[i] = bwd_log[i + 1] + np.log(scale)

    p_match = np.empty((n, s, k))
    p_echo = np.zeros((n, s, k))
    with np.errstate(divide="ignore"):  # a pair no matching uses has probability exactly 0
        for i in range(s):
            log_rel = fwd_log[i] + bwd_log[i + 1] - log_z
            for j in range(k):
                pair = (_split(fwd[i], j, k)[0] * _split(bwd[i + 1], j, k)[1]).sum(axis=(0, 1))
                p_match[:, i, j] = np.exp(np.log(pair) + log_w[:, i, j] + log_rel)
            for j, jj, echo, without, both in pairs:
                term = (fwd[i][without] * bwd[i + 1][both]).sum(axis=0)
                p_pair = np.exp(np.log(term) + log_w[:, i, j] + np.log(echo) + log_rel)
                p_match[:, i, j] += p_pair
                p_match[:, i, jj] += p_pair
                p_echo[:, i, jj] += p_pair
    return log_z, p_match, p_echo


def from_config(_config: Config) -> Engine:
    """The exact engine (it has no settings)."""
    return associate
