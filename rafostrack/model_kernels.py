"""The measurement model's compiled kernels: the arrival-time error density, its CDF, and
the association factors of a window for many particles at once.

A direct arrival's error is Gaussian, r ~ N(0, sigma^2); a fraction eps of arrivals comes by
a longer path, delayed by an Exp(mean tau) delay, r = g + d (an exponentially modified
Gaussian, EMG). With z = r / sigma:

    f(r) = (1 - eps) phi(z) / sigma + eps EMG(r),
    log EMG(r) = -log tau + sigma^2 / (2 tau^2) - r / tau + log Phi(z - sigma / tau),
    F(r) = Phi(z) - eps exp(sigma^2 / (2 tau^2) - r / tau) Phi(z - sigma / tau).

`log_ndtr` is log Phi accurate in both tails: log(erfc(-z / sqrt 2) / 2) down to z = -35,
below it the asymptotic series log Phi(z) = -z^2/2 - log(-z) - log sqrt(2 pi)
+ log(1 - 1/z^2 + 3/z^4 - 15/z^6 + 105/z^8 - 945/z^10) (error < 1e-14 there).

The scalar functions (`logpdf_c`, `cdf_c`, with constants computed once by `constants`) are
compiled by numba and called from `factors_kernel`; `toa_logpdf_ufunc` and `toa_cdf_ufunc`
are the same code as numpy ufuncs (broadcasting over arrays), so every caller uses one
implementation. (Kernels calling one another live in this one module: numba's cache of a
kernel is refreshed when its own file changes, not when a kernel it calls elsewhere does.)

`factors_kernel` computes log w_ij and log u_i (`model` module docstring) in one pass. A
signal more than `FAR_EARLY` sds before a beacon's predicted arrival, or more than
`FAR_LATE` multipath delays after it (`FAR_LATE_DIRECT` sds when there is no multipath), gets
log w_ij = -inf: its density there is below e^-40 of its peak, so the term weighs less than
~1e-16 of the unmatched option (which weighs 1) and changes log Z by less than ~1e-15; the
engines skip such terms.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, vectorize

_LOG_SQRT_2PI = 0.5 * math.log(2.0 * math.pi)
FAR_EARLY = 9.0  # sds before the prediction: Gaussian e^-40, the delayed copy less
FAR_LATE = 40.0  # mean delays after it: the delayed copy e^-40
FAR_LATE_DIRECT = 9.0  # sds after it without multipath
_SQRT_HALF = math.sqrt(0.5)
_EXP_UNDERFLOW = 746.0  # math.exp(-x) == 0.0 for x above ~745.13


@njit(cache=True, nogil=True)
def log_ndtr(z: float) -> float:  # pragma: no cover - compiled
    """log Phi(z) (module docstring)."""
    if z > -35.0:
        return math.log(0.5 * math.erfc(-z * _SQRT_HALF))
    q = 1.0 / (z * z)
    series = 1.0 - q * (1.0 - q * (3.0 - q * (15.0 - q * (105.0 - q * 945.0))))
    return -0.5 * z * z - math.log(-z) - _LOG_SQRT_2PI + math.log(series)


@njit(cache=True, nogil=True)
def ndtr(z: float) -> float:  # pragma: no cover - compiled
    return 0.5 * math.erfc(-z * _SQRT_HALF)


@njit(cache=True, nogil=True)
def constants(sigma: float, eps: float, tau: float):  # pragma: no cover - compiled
    """The density's constants, computed once per call of a kernel: (sigma, eps, 1 / tau,
    sigma / tau, log(1 - eps) - log sigma - log sqrt(2 pi), log eps - log tau + sigma^2 / (2 tau^2),
    sigma^2 / (2 tau^2))."""
    log_direct = math.log1p(-eps) - math.log(sigma) - _LOG_SQRT_2PI
    half_shift2 = sigma * sigma / (2.0 * tau * tau)
    log_delayed = (math.log(eps) - math.log(tau) + half_shift2) if eps > 0.0 else -math.inf
    return sigma, eps, 1.0 / tau, sigma / tau, log_direct, log_delayed, half_shift2


@njit(cache=True, nogil=True)
def logpdf_c(r: float, c) -> float:  # pragma: no cover - compiled
    """log f(r) with the `constants` c. Where z - sigma / tau > 8, Phi(z - sigma / tau) is 1
    to double precision and is not evaluated."""
    sigma, eps, inv_tau, shift, log_direct, log_delayed, _ = c
    z = r / sigma
    a = log_direct - 0.5 * z * z
    if eps == 0.0:
        return a
    u = z - shift
    b = log_delayed - r * inv_tau + (log_ndtr(u) if u < 8.0 else 0.0)
    top = max(a, b)
    gap = abs(a - b)
    if gap > _EXP_UNDERFLOW:  # exp(-gap) is 0.0: the sum below is `top`, bit for bit
        return top
    return top + math.log1p(math.exp(-gap))


@njit(cache=True, nogil=True)
def cdf_c(r: float, c) -> float:  # pragma: no cover - compiled
    """F(r) with the `constants` c; 0 below -40 sigma and its tail's closed form above."""
    sigma, eps, inv_tau, shift, _, _, half_shift2 = c
    z = r / sigma
    if z < -40.0:
        return 0.0
    gauss = ndtr(z) if z < 9.0 else 1.0
    if eps == 0.0:
        return gauss
    u = z - shift
    tail = math.exp(half_shift2 - r * inv_tau + (log_ndtr(u) if u < 8.0 else 0.0))
    return (1.0 - eps) * gauss + eps * (gauss - tail)


@njit(cache=True, nogil=True)
def _logpdf(r: float, sigma: float, eps: float, tau: float) -> float:  # pragma: no cover - compiled
    return logpdf_c(r, constants(sigma, eps, tau))


@njit(cache=True, nogil=True)
def _cdf(r: float, sigma: float, eps: float, tau: float) -> float:  # pragma: no cover - compiled
    return cdf_c(r, constants(sigma, eps, tau))


@vectorize(["float64(float64, float64, float64, float64)"], cache=True)
def toa_logpdf_ufunc(r, sigma, eps, tau):  # pragma: no cover - compiled
    return _logpdf(r, sigma, eps, tau)


@vectorize(["float64(float64, float64, float64, float64)"], cache=True)
def toa_cdf_ufunc(r, sigma, eps, tau):  # pragma: no cover - compiled
    return _cdf(r, sigma, eps, tau)


@vectorize(["float64(float64)"], cache=True)
def log_ndtr_ufunc(z):  # pragma: no cover - compiled
    return log_ndtr(z)


@njit(cache=True, nogil=True)
def factors_kernel(  # pragma: no cover - compiled
    mu, p_detect, toa, sigma, eps, tau, log_lam, h, ranked, signal_term, log_match, log_unheard
):
    """log w_ij (P, s, K) and log u_i (P, s) of one window (module docstring): `toa`
    (1 or P, K) and the horizon `h` (1 or P,), one row shared by all particles, or one per
    particle (a batch of windows); `signal_term` (rows of `toa`, K), added to every
    log w_ij of signal j (e.g. the echo model's), or (0, K): none."""
    n, s = mu.shape
    k = toa.shape[1]
    shared = toa.shape[0] == 1
    added = signal_term.shape[0] > 0
    c = constants(sigma, eps, tau)
    early = -FAR_EARLY * sigma
    late = FAR_LATE * tau if eps > 0.0 else FAR_LATE_DIRECT * sigma
    for p in range(n):
        row = 0 if shared else p
        for i in range(s):
            log_pd = math.log(p_detect[p, i])
            for j in range(k):
                r = toa[row, j] - mu[p, i]
                if r < early or r > late:
                    log_match[p, i, j] = -np.inf
                elif added:
                    log_match[p, i, j] = (log_pd + logpdf_c(r, c) - log_lam) + signal_term[row, j]
                else:
                    log_match[p, i, j] = log_pd + logpdf_c(r, c) - log_lam
            if ranked:
                p_in = cdf_c(h[row] - mu[p, i], c) - cdf_c(-mu[p, i], c)
                log_unheard[p, i] = math.log1p(-p_detect[p, i] * min(max(p_in, 0.0), 1.0))
            else:
                log_unheard[p, i] = math.log1p(-p_detect[p, i])
