"""The exact association sum as a compiled kernel (`exact` engine).

The dynamic programme of `engines.exact` (forward tables F_i over subsets of signals,
backward tables B_i, pair marginals from F_{i-1} w_ij B_i; echo pairs as extra terms),
written as loops that numba compiles. Particles go through in blocks of `LANES`, each table
entry a row of `LANES` numbers, so that the innermost loops run over particles and
vectorise; every particle's arithmetic is the same sequence of operations whatever its
block or lane, so results are the same bits on every run, thread count and block size.

Each stage updates its table in place: F_i(m) = F_{i-1}(m) + sum_{j in m} w_ij F_{i-1}(m - j)
(+ pairs) reads only masks below m, so the masks are visited in decreasing order (the
backward tables, in increasing order). Tables are not rescaled at every stage: a bound on
the largest entry (the previous bound times 1 + sum_j w_ij + pairs) is kept, and a lane is
rescaled to a maximum of 1 (its log scale kept aside) only when the bound passes
`RESCALE_ABOVE`; with the unmatched option weighing 1, no entry can underflow.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

LANES = 32
RESCALE_ABOVE = 1e150
LOG_NEGLIGIBLE = -690.0  # exp below ~1e-300: the term is 0


@njit(cache=True, nogil=True, boundscheck=False)
def _weights(log_match, log_unheard, p0, nl, pair_j, pair_e, w, pw, active, active_pair):  # pragma: no cover
    """w[i, j, l] = exp(log_match - log_unheard) of particle p0 + l; pw[i, q, l] =
    w[i, pair_j[q], l] * E_q (E of the particle's row of `pair_e`: one row shared by all,
    or one per particle); and whether any lane of the block has a term above 1e-300 (the
    others are skipped)."""
    shared = pair_e.shape[0] == 1
    s, k = log_match.shape[1], log_match.shape[2]
    active[:, :] = False
    for lane in range(nl):  # particle by particle: its factors lie together in memory
        for i in range(s):
            log_u = log_unheard[p0 + lane, i]
            for j in range(k):
                x = log_match[p0 + lane, i, j] - log_u
                if x > LOG_NEGLIGIBLE:
                    w[i, j, lane] = math.exp(x)
                    active[i, j] = True
                else:
                    w[i, j, lane] = 0.0
    for i in range(s):
        for q in range(pair_j.shape[0]):
            any_term = False
            for lane in range(nl):
                pw[i, q, lane] = w[i, pair_j[q], lane] * pair_e[0 if shared else p0 + lane, q]
                any_term = any_term or pw[i, q, lane] > 0.0
            active_pair[i, q] = any_term


@njit(cache=True, nogil=True, boundscheck=False)
def _bound_step(w, pw, i, nl, table, bound, log_scale):  # pragma: no cover - compiled
    """After stage i: update each lane's bound on its largest entry; rescale lanes past it."""
    k, n_pairs, n_masks = w.shape[1], pw.shape[1], table.shape[0]
    for lane in range(nl):
        grow = 1.0
        for j in range(k):
            grow += w[i, j, lane]
        for q in range(n_pairs):
            grow += pw[i, q, lane]
        bound[lane] *= grow
        if bound[lane] > RESCALE_ABOVE:
            top = 0.0
            for m in range(n_masks):
                if table[m, lane] > top:
                    top = table[m, lane]
            for m in range(n_masks):
                table[m, lane] /= top
            log_scale[lane] += math.log(top)
            bound[lane] = 1.0


@njit(cache=True, nogil=True, boundscheck=False)
def _forward_stage(w, pw, i, k, pair_j, pair_jj, nl, table, active, active_pair):  # pragma: no cover - compiled
    """F_i from F_{i-1}, in place (masks in decreasing order)."""
    n_masks = table.shape[0]
    for m in range(n_masks - 1, 0, -1):
        for j in range(k):
            bit = 1 << j
            if m & bit and active[i, j]:
                src = m ^ bit
                for lane in range(nl):
                    table[m, lane] += w[i, j, lane] * table[src, lane]
        for q in range(pair_j.shape[0]):
            both = (1 << pair_j[q]) | (1 << pair_jj[q])
            if m & both == both and active_pair[i, q]:
                src = m ^ both
                for lane in range(nl):
                    table[m, lane] += pw[i, q, lane] * table[src, lane]


@njit(cache=True, nogil=True, boundscheck=False)
def _backward_stage(w, pw, i, k, pair_j, pair_jj, nl, table, active, active_pair):  # pragma: no cover - compiled
    """B_{i-1} from B_i, in place (masks in increasing order)."""
    n_masks = table.shape[0]
    for m in range(n_masks - 1):
        for j in range(k):
            bit = 1 << j
            if m & bit == 0 and active[i, j]:
                dst = m | bit
                for lane in range(nl):
                    table[m, lane] += w[i, j, lane] * table[dst, lane]
        for q in range(pair_j.shape[0]):
            both = (1 << pair_j[q]) | (1 << pair_jj[q])
            if m & both == 0 and active_pair[i, q]:
                dst = m | both
                for lane in range(nl):
                    table[m, lane] += pw[i, q, lane] * table[dst, lane]


@njit(cache=True, nogil=True, boundscheck=False)
def unheard_total(log_unheard, out):  # pragma: no cover - compiled
    """out[p] = sum_i log u_i of particle p, in beacon order (`row_sum`, which the window
    evidence's kernel, `likelihoods._window_kernel`, shares)."""
    for p in range(log_unheard.shape[0]):
        out[p] = row_sum(log_unheard[p])


@njit(cache=True, nogil=True, inline="always")
def row_sum(values):  # pragma: no cover - compiled
    """sum of `values` (1-d) in order, from 0."""
    total = 0.0
    for i in range(values.shape[0]):
        total += values[i]
    return total


@njit(cache=True, nogil=True, boundscheck=False)
def associate_kernel(
    log_match, log_unheard, pair_j, pair_jj, log_e, marginals, log_z, p_match, p_echo
):  # pragma: no cover
    """Fill log_z (P,) (log Z less sum_i log u_i), and with `marginals` p_match and p_echo
    (P, s, K), from log w_ij (P, s, K), log u_i (P, s) and the echo pairs (j, j') with their
    log E_jj' (1 or P, pairs: shared, or per particle); each beacon's factors are divided by
    u_i (module docstring of `exact`). Block by block of `LANES` particles, each with its
    own tables (`_associate_block`)."""
    pair_e = np.exp(log_e)
    for p0 in range(0, log_match.shape[0], LANES):
        _associate_block(log_match, log_unheard, pair_j, pair_jj, log_e, pair_e, marginals, p0, log_z, p_match, p_echo)


@njit(cache=True, nogil=True, boundscheck=False, parallel=True)
def associate_kernel_threaded(
    log_match, log_unheard, pair_j, pair_jj, log_e, marginals, log_z, p_match, p_echo
):  # pragma: no cover
    """`associate_kernel` on numba's threads, a block each (`model.parallel`)."""
    pair_e = np.exp(log_e)
    for block in prange((log_match.shape[0] + LANES - 1) // LANES):
        p0 = np.intp(block) * LANES
        _associate_block(log_match, log_unheard, pair_j, pair_jj, log_e, pair_e, marginals, p0, log_z, p_match, p_echo)


@njit(cache=True, nogil=True, boundscheck=False)
def _associate_block(
    log_match, log_unheard, pair_j, pair_jj, log_e, pair_e, marginals, p0, log_z, p_match, p_echo
):  # pragma: no cover
    """`associate_kernel` on the block of particles from p0 (its own tables)."""
    n, s, k = log_match.shape
    shared = log_e.shape[0] == 1
    n_masks = 1 << k
    n_pairs = pair_j.shape[0]
    w = np.empty((s, k, LANES))
    pw = np.empty((s, n_pairs, LANES))
    fwd = np.empty((s + 1 if marginals else 1, n_masks, LANES))
    fwd_log = np.empty((s + 1 if marginals else 1, LANES))
    bwd = np.empty((n_masks, LANES))
    bwd_log = np.empty(LANES)
    bound = np.empty(LANES)
    total = np.empty(LANES)
    active = np.empty((s, k), dtype=np.bool_)
    active_pair = np.empty((s, n_pairs), dtype=np.bool_)
    heard = np.empty(s, dtype=np.bool_)  # beacon i has a term above 1e-300 in the block
    nl = min(LANES, n - p0)
    _weights(log_match, log_unheard, p0, nl, pair_j, pair_e, w, pw, active, active_pair)
    for i in range(s):
        heard[i] = active[i].any() or active_pair[i].any()
    for m in range(n_masks):
        for lane in range(nl):
            fwd[0, m, lane] = 0.0
    for lane in range(nl):
        fwd[0, 0, lane] = 1.0
        fwd_log[0, lane] = 0.0
        bound[lane] = 1.0
    for i in range(s):
        table = fwd[i + 1] if marginals else fwd[0]
        if marginals:
            for m in range(n_masks):
                for lane in range(nl):
                    table[m, lane] = fwd[i, m, lane]
        log_scale = fwd_log[i + 1] if marginals else fwd_log[0]
        if marginals:
            for lane in range(nl):
                log_scale[lane] = fwd_log[i, lane]
        if heard[i]:  # else F_i = F_{i-1} and the bound does not grow: nothing to do
            _forward_stage(w, pw, i, k, pair_j, pair_jj, nl, table, active, active_pair)
            _bound_step(w, pw, i, nl, table, bound, log_scale)
    last = fwd[s] if marginals else fwd[0]
    last_log = fwd_log[s] if marginals else fwd_log[0]
    for lane in range(nl):
        acc = 0.0
        for m in range(n_masks):
            acc += last[m, lane]
        total[lane] = last_log[lane] + math.log(acc)
        log_z[p0 + lane] = total[lane]
    if not marginals:
        return
    for m in range(n_masks):
        for lane in range(nl):
            bwd[m, lane] = 1.0
    for lane in range(nl):
        bwd_log[lane] = 0.0
        bound[lane] = 1.0
    for i in range(s - 1, -1, -1):
        # Marginals of beacon i: F_i (before it, fwd[i]) x w_ij x B_i (after it, bwd).
        for lane in range(nl):
            rel = fwd_log[i, lane] + bwd_log[lane] - total[lane]
            for j in range(k):
                bit = 1 << j
                acc = 0.0
                if not active[i, j]:
                    p_match[p0 + lane, i, j] = 0.0
                    p_echo[p0 + lane, i, j] = 0.0
                    continue
                for m in range(n_masks):
                    if m & bit == 0:
                        acc += fwd[i, m, lane] * bwd[m | bit, lane]
                if acc > 0.0:  # in log space: w and the scales may be far from 1
                    p_match[p0 + lane, i, j] = math.exp(
                        math.log(acc) + log_match[p0 + lane, i, j] - log_unheard[p0 + lane, i] + rel
                    )
                else:
                    p_match[p0 + lane, i, j] = 0.0
                p_echo[p0 + lane, i, j] = 0.0
            for q in range(n_pairs):
                if not active_pair[i, q]:
                    continue
                both = (1 << pair_j[q]) | (1 << pair_jj[q])
                acc = 0.0
                for m in range(n_masks):
                    if m & both == 0:
                        acc += fwd[i, m, lane] * bwd[m | both, lane]
                if acc <= 0.0:
                    continue
                log_wq = log_match[p0 + lane, i, pair_j[q]] - log_unheard[p0 + lane, i]
                pair = math.exp(math.log(acc) + log_wq + log_e[0 if shared else p0 + lane, q] + rel)
                p_match[p0 + lane, i, pair_j[q]] += pair
                p_match[p0 + lane, i, pair_jj[q]] += pair
                p_echo[p0 + lane, i, pair_jj[q]] += pair
        if heard[i]:
            _backward_stage(w, pw, i, k, pair_j, pair_jj, nl, bwd, active, active_pair)
            _bound_step(w, pw, i, nl, bwd, bound, bwd_log)
