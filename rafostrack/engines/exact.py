"""Exact association sum and marginals by dynamic programming over subsets of signals.

Beacons are added one at a time; the state is the set (bitmask) of signals already
matched. Forward: F_i(m) = weight of all ways beacons 1..i cover exactly m,
    F_i(m) = u_i F_{i-1}(m) + sum_{j in m} w_ij F_{i-1}(m - {j}),
and backward: B_i(m) = weight of all completions by beacons i+1..s when m is taken,
    B_{i-1}(m) = u_i B_i(m) + sum_{j not in m} w_ij B_i(m + {j}),   B_s(m) = 1
(unmatched signals are clutter, weight 1 after the model's normalisation). Then
    Z = sum_m F_s(m),  P(i <-> j) = sum_{m not containing j} F_{i-1}(m) w_ij B_i(m + {j}) / Z.
Echo pairs (`model.measurement.echo_factors`): a beacon may also take two signals j < j' at once,
    F_i(m) += w_ij E_jj' F_{i-1}(m - {j, j'}),   B_{i-1}(m) += w_ij E_jj' B_i(m + {j, j'}),
and such a pair counts towards both signals' marginals.
Cost O(s r 2^r) per particle (O(s r^2 2^r) with echoes), in a compiled kernel, one particle
at a time (`_exact_kernel`). Arithmetic is linear but scaled: each beacon's factors are
divided by u_i (so the "unmatched" option weighs 1 and no table entry can shrink), and each
table is renormalised to a maximum of 1 with its log-scale kept aside. Marginals are
assembled in log space. Accurate (1e-9 relative, tests/test_engines.py) for log(w_ij/u_i)
within +-300; realistic windows stay within +-40.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..config import Config
from ..errors import InputError
from ..model.parallel import threaded
from ._exact_kernel import associate_kernel, associate_kernel_threaded, unheard_total
from .base import Association, Engine

MAX_SIGNALS = 12


def associate(
    log_match: NDArray, log_unheard: NDArray, *, marginals: bool = True, log_echo: NDArray | None = None
) -> Association:
    """Exact log Z and pair marginals (see module docstring); refuses K > 12.

    `log_echo` (K, K), or (P, K, K) for one window per particle (a batch of windows with
    the same numbers of beacons and signals): the echo pair terms log E_jj'
    (`model.measurement.echo_factors`); a beacon may then take a pair j < j' with weight w_ij E_jj',
    and both signals are its own.
    `marginals=False` runs the forward pass only (a third of the cost) and returns NaN
    marginals.
    """
    n, s, k = log_match.shape
    if k > MAX_SIGNALS:
        raise InputError(
            f"the exact method handles at most {MAX_SIGNALS} stored signals per window "
            f"(cost grows as 2^r); this window has {k}: use --engine bp"
        )
    log_u_total = np.empty(n)
    unheard_total(np.ascontiguousarray(log_unheard, dtype=np.float64), log_u_total)
    if k == 0 or s == 0:
        return Association(log_u_total, np.zeros((n, s, k)))
    pair_j, pair_jj, log_e = echo_pairs(log_echo, k)
    log_z = np.empty(n)
    shape = (n, s, k) if marginals else (0, s, k)
    p_match, p_echo = np.empty(shape), np.empty(shape)
    kernel = associate_kernel_threaded if threaded(n) else associate_kernel
    kernel(
        np.ascontiguousarray(log_match, dtype=np.float64),
        np.ascontiguousarray(log_unheard, dtype=np.float64),
        pair_j,
        pair_jj,
        log_e,
        marginals,
        log_z,
        p_match,
        p_echo,
    )
    if not marginals:  # a read-only NaN view: no memory
        return Association(log_z + log_u_total, np.broadcast_to(np.nan, (n, s, k)))
    return Association(log_z + log_u_total, p_match, p_echo if len(pair_j) else None)


def echo_pairs(log_echo: NDArray | None, k: int) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64]]:
    """The echo pairs j < j' with E_jj' > 0 (for some particle): their signal indices and
    log E, (1, pairs) or (P, pairs)."""
    if log_echo is None:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((1, 0))
    rows = log_echo.reshape(-1, k, k)
    j, jj = np.nonzero(np.triu(np.isfinite(rows).any(axis=0), 1))
    return j.astype(np.int64), jj.astype(np.int64), np.ascontiguousarray(rows[:, j, jj], dtype=np.float64)


def from_config(_config: Config) -> Engine:
    """The exact engine (it has no settings)."""
    return associate
