"""A window's ranked evidence for a cloud in one compiled pass (the `exact` engine's).

Block by block of `LANES` particles, with no array over the whole cloud between the
stages: the ranges to the window's beacons (`model.geodesy`'s expansion about the cloud's
centre, the exact formula where its bound fails), the predicted arrivals mu_i = delay_i +
range_i / c_i (+ the particle's clock), the detection probabilities Pd_i
(`measurement.detection_prob`), the factors log w_ij and log u_i (`model.kernels`), the
exact association sum with its marginals (`engines._exact_kernel`) and log p(T | X) = K log
Lambda - Lambda h + log Z. Each stage is the same sequence of operations as its numpy
composition (`likelihoods.arrivals.RankedArrivals` with another engine's path), so the
results are the same bits, on every run, block size and thread count
(tests/test_window_kernel.py).

numba's cache of a kernel is refreshed when its own file changes, not when a kernel it
calls in another module does. `DEPENDENCIES_SHA256` is the digest of the modules this one
compiles in (`dependencies_sha256`, checked by tests/test_window_kernel.py): changing one of
them means changing the digest here, which refreshes this module's cache.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
from numba import njit, prange

from ..engines._exact_kernel import LANES, _associate_block, row_sum
from ..model.geodesy import (
    EXPANSION_STEP_KM,
    EXPANSION_TOLERANCE_M,
    _expanded_point,
    _expansion,
    exact_ranges_row,
)
from ..model.kernels import _factors_row, constants, detection_c

DEPENDENCIES = ("engines/_exact_kernel.py", "model/geodesy.py", "model/kernels.py")
DEPENDENCIES_SHA256 = "efa37f14f5cd12c9acef4ea8b2b20efba92edff6d07c982e390e3faab41ee1cb"

# Rows of the per-beacon terms `beacon` (6, s), and entries of the window's `terms` (9,):
# its signals' and the measurement model's (`window_evidence_kernel`).
LAT, LON, DELAY_S, SPEED_M_S, P_PEAK, HALF_RANGE_KM = range(6)
LOG_INTENSITY, HORIZON_S, LOG_BASE, RANKED = range(4)
SIGMA_S, MULTIPATH_FRACTION, MULTIPATH_DELAY_S, MULTIPATH_SHAPE, FALLOFF_KM = range(4, 9)


def dependencies_sha256() -> str:
    """The digest of `DEPENDENCIES`' sources, in order."""
    package = Path(__file__).resolve().parent.parent
    digest = hashlib.sha256()
    for name in DEPENDENCIES:
        digest.update((package / name).read_bytes())
    return digest.hexdigest()


@njit(cache=True, nogil=True, boundscheck=False)
def window_evidence_kernel(  # pragma: no cover - compiled
    lat, lon, clock_s, expanded, near, far, beacon, toa, terms, no_echo, ratio, pairs, log_e, marginals, loglik, p_match
):  # fmt: skip
    """loglik (P,) = log p(T | X_p) of one window, and with `marginals` p_match (P, s, K).

    `clock_s` (P,), or (0,) without a clock in the state; the ranges `expanded` about the
    cloud's centre (`geodesy.expands_about_centre`), or else by the exact formula from the
    particles' and the beacons' point terms `near` (6, P) and `far` (6, s)
    (`geodesy.stacked_point_terms`, as `geodesy.range_matrix_m` takes them); `beacon`
    (6, s): rows `LAT` .. `HALF_RANGE_KM`, the model's values where a beacon has none;
    `toa` (1, K); `terms` (`LOG_INTENSITY` .. `FALLOFF_KM`, the detection fall-off's width);
    `no_echo` (1, K), the echo model's per-signal term, or (0, *): none; `ratio` (K,), each
    signal's source-vs-clutter log ratio, or (0,); the echo pairs (j, j') as `pairs`
    (2, pairs) with their log E_jj' (1, pairs). Block by block (`_evidence_block`)."""
    centre, coef, far = _ranges_setup(lat, lon, expanded, far, beacon)
    c = constants(terms[SIGMA_S], terms[MULTIPATH_FRACTION], terms[MULTIPATH_DELAY_S], np.int64(terms[MULTIPATH_SHAPE]))
    pair_e = np.exp(log_e)
    for p0 in range(0, lat.shape[0], LANES):
        _evidence_block(p0, lat, lon, clock_s, near, beacon, toa, c, terms, no_echo, ratio, pairs, log_e, pair_e,
                        marginals, expanded, centre, coef, far, loglik, p_match)  # fmt: skip


@njit(cache=True, nogil=True, boundscheck=False, parallel=True)
def window_evidence_kernel_threaded(  # pragma: no cover - compiled
    lat, lon, clock_s, expanded, near, far, beacon, toa, terms, no_echo, ratio, pairs, log_e, marginals, loglik, p_match
):  # fmt: skip
    """`window_evidence_kernel` on numba's threads, a block each (`model.parallel`)."""
    centre, coef, far = _ranges_setup(lat, lon, expanded, far, beacon)
    c = constants(terms[SIGMA_S], terms[MULTIPATH_FRACTION], terms[MULTIPATH_DELAY_S], np.int64(terms[MULTIPATH_SHAPE]))
    pair_e = np.exp(log_e)
    for block in prange((lat.shape[0] + LANES - 1) // LANES):
        p0 = np.intp(block) * LANES
        _evidence_block(p0, lat, lon, clock_s, near, beacon, toa, c, terms, no_echo, ratio, pairs, log_e, pair_e,
                        marginals, expanded, centre, coef, far, loglik, p_match)  # fmt: skip


@njit(cache=True, nogil=True)
def _ranges_setup(lat, lon, expanded, far, beacon):  # pragma: no cover - compiled
    """Where the ranges are `expanded` about the cloud's centre, the expansion's centre and
    coefficients and the beacons' point terms (6, s); else placeholders and `far`."""
    if expanded:
        return _expansion(lat, lon, beacon[LAT], beacon[LON], EXPANSION_STEP_KM)
    return np.empty(5), np.empty((beacon.shape[1], 6)), far


@njit(cache=True, nogil=True, boundscheck=False)
def _evidence_block(  # pragma: no cover - compiled
    p0, lat, lon, clock_s, near, beacon, toa, c, terms, no_echo, ratio, pairs, log_e, pair_e, marginals, expanded,
    centre, coef, far, loglik, p_match
):  # fmt: skip
    """The block of particles from p0: their factors (`_block_factors`), their association
    sum and marginals (`engines._exact_kernel._associate_block`), and log p(T | X) =
    the shared term + log Z (the sum's, times prod_i u_i)."""
    n, s, k = lat.shape[0], beacon.shape[1], toa.shape[1]
    nl = min(LANES, n - p0)
    log_match = np.empty((nl, s, k))
    log_unheard = np.empty((nl, s))
    _block_factors(p0, nl, lat, lon, clock_s, near, beacon, toa, c, terms, no_echo, ratio, expanded, centre, coef,
                   far, log_match, log_unheard)  # fmt: skip
    log_z = np.empty(nl)
    block_match = p_match[p0 : p0 + nl] if marginals else p_match[0:0]
    p_echo = np.empty((nl if marginals else 0, s, k))
    _associate_block(
        log_match, log_unheard, pairs[0], pairs[1], log_e, pair_e, marginals, 0, log_z, block_match, p_echo
    )
    for lane in range(nl):
        loglik[p0 + lane] = terms[LOG_BASE] + (log_z[lane] + row_sum(log_unheard[lane]))


@njit(cache=True, nogil=True, boundscheck=False)
def _block_factors(  # pragma: no cover - compiled
    p0, nl, lat, lon, clock_s, near, beacon, toa, c, terms, no_echo, ratio, expanded, centre, coef, far, log_match,
    log_unheard
):  # fmt: skip
    """log w_ij (nl, s, K) and log u_i (nl, s) of the block's particles: their ranges, mu_i
    and Pd_i (`measurement.predicted_toa_s`, `detection_prob`), then `kernels._factors_row`,
    and each signal's source-vs-clutter log ratio added to its w_ij."""
    s, k = beacon.shape[1], toa.shape[1]
    ranges = np.empty((nl, s))
    mu = np.empty((nl, s))
    p_detect = np.empty((nl, s))
    lat_b, lon_b = lat[p0 : p0 + nl], lon[p0 : p0 + nl]
    falloff_km = terms[FALLOFF_KM]
    for lane in range(nl):
        if expanded:
            _expanded_point(lane, lat_b, lon_b, centre, coef, far, EXPANSION_TOLERANCE_M / 1e3, ranges)
        else:
            exact_ranges_row(near, p0 + lane, far, ranges[lane])
        for i in range(s):
            mu[lane, i] = beacon[DELAY_S, i] + ranges[lane, i] / beacon[SPEED_M_S, i]
            if clock_s.shape[0]:
                mu[lane, i] = mu[lane, i] + clock_s[p0 + lane]
            p_detect[lane, i] = detection_c(ranges[lane, i], beacon[P_PEAK, i], beacon[HALF_RANGE_KM, i], falloff_km)
    sigma, eps, tau = terms[SIGMA_S], terms[MULTIPATH_FRACTION], terms[MULTIPATH_DELAY_S]
    log_lam, horizon, ranked = terms[LOG_INTENSITY], terms[HORIZON_S : HORIZON_S + 1], terms[RANKED] > 0.0
    for lane in range(nl):
        _factors_row(lane, mu, p_detect, toa, sigma, eps, tau, log_lam, horizon, ranked, no_echo, c, log_match,
                     log_unheard)  # fmt: skip
        if ratio.shape[0]:
            for i in range(s):
                for j in range(k):
                    log_match[lane, i, j] = log_match[lane, i, j] + ratio[j]
