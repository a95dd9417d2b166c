"""The measurement model's compiled kernels: the arrival-time error density, its CDF, and
the association factors of a window for many particles at once.

A direct arrival's error is Gaussian, r ~ N(0, sigma^2); a fraction eps of arrivals comes by
a longer path, delayed by d, r = g + d. The delay is Gamma(shape k, scale theta = tau / k),
mean tau, with k = 1 (an exponential: an exponentially modified Gaussian, EMG) or k = 2 (an
Erlang delay, no mass at 0: a reflected path is never as short as the direct one). With
z = r / sigma, u = z - sigma / theta, c = sigma^2 / (2 theta^2) - r / theta, and
psi(u) = u Phi(u) + phi(u) (the integral of Phi up to u):

    f(r) = (1 - eps) phi(z) / sigma + eps f_d(r),
    k = 1: log f_d(r) = -log theta + c + log Phi(u),
           F_d(r) = Phi(z) - exp(c) Phi(u);
    k = 2: log f_d(r) = log sigma - 2 log theta + c + log psi(u),
           F_d(r) = Phi(z) - exp(c) (Phi(u) + (sigma / theta) psi(u)),
    F(r) = (1 - eps) Phi(z) + eps F_d(r).

(From the integrals over d > 0 of d^(k-1) exp(-d / theta) phi((r - d) / sigma), which
complete the square to Gaussian moments about r - sigma^2 / theta.)

`log_ndtr` is log Phi accurate in both tails: log(erfc(-z / sqrt 2) / 2) down to z = -35,
below it the asymptotic series log Phi(z) = -z^2/2 - log(-z) - log sqrt(2 pi)
+ log(1 - 1/z^2 + 3/z^4 - 15/z^6 + 105/z^8 - 945/z^10) (error < 1e-14 there). `log_psi`
likewise: log psi(u) directly above u = -35 (phi(u) - |u| Phi(u) loses about log10(u^2)
digits to cancellation there, < 4), below it log psi(u) = log phi(u) - 2 log(-u)
+ log(1 - 3/u^2 + 15/u^4 - 105/u^6 + 945/u^8 - 10395/u^10).

The scalar functions (`logpdf_c`, `cdf_c`, with constants computed once by `constants`) are
compiled by numba and inlined into `factors_kernel` (numba's IR inlining: the delay law's
branch then costs nothing measurable; without it the kernel ran 4-9% slower);
`toa_logpdf_kernel` and `toa_cdf_kernel` are the same code over flat arrays, the constants
computed once per call, so every caller uses one implementation. (Kernels calling one
another live in this one module: numba's cache of a kernel is refreshed when its own file
changes, not when a kernel it calls elsewhere does.)

`factors_kernel` computes log w_ij and log u_i (`model` module docstring) in one pass. A
signal more than `FAR_EARLY` sds before a beacon's predicted arrival, or more than
`FAR_LATE` mean multipath delays after it (`FAR_LATE_DIRECT` sds without multipath), gets
log w_ij = -inf: its density there is below e^-40 of its peak, so the term weighs less than
~1e-16 of the unmatched option (which weighs 1) and changes log Z by less than ~1e-15; the
engines skip such terms.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

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
def log_psi(u: float) -> float:  # pragma: no cover - compiled
    """log psi(u), psi(u) = u Phi(u) + phi(u) (module docstring)."""
    if u > -35.0:
        return math.log(u * ndtr(u) + math.exp(-0.5 * u * u - _LOG_SQRT_2PI))
    q = 1.0 / (u * u)
    series = 1.0 - q * (3.0 - q * (15.0 - q * (105.0 - q * (945.0 - q * 10395.0))))
    return -0.5 * u * u - _LOG_SQRT_2PI - 2.0 * math.log(-u) + math.log(series)


@njit(cache=True, nogil=True, inline="always")
def _log_add(a: float, b: float) -> float:  # pragma: no cover - compiled
    """log(e^a + e^b)."""
    top = max(a, b)
    gap = abs(a - b)
    if gap > _EXP_UNDERFLOW:  # exp(-gap) is 0.0: the sum below is `top`, bit for bit
        return top
    return top + math.log1p(math.exp(-gap))


@njit(cache=True, nogil=True)
def constants(sigma: float, eps: float, tau: float, shape: int):  # pragma: no cover - compiled
    """The density's constants, computed once per call of a kernel (theta = tau / shape):
    (sigma, eps, 1 / theta, sigma / theta, log(1 - eps) - log sigma - log sqrt(2 pi),
    log eps + the delayed part's constant (module docstring), sigma^2 / (2 theta^2), shape)."""
    theta = tau / shape
    log_direct = math.log1p(-eps) - math.log(sigma) - _LOG_SQRT_2PI
    half_shift2 = sigma * sigma / (2.0 * theta * theta)
    if eps == 0.0:
        log_delayed = -math.inf
    elif shape == 1:
        log_delayed = math.log(eps) - math.log(theta) + half_shift2
    else:
        log_delayed = math.log(eps) + math.log(sigma) - 2.0 * math.log(theta) + half_shift2
    return sigma, eps, 1.0 / theta, sigma / theta, log_direct, log_delayed, half_shift2, shape


@njit(cache=True, nogil=True, inline="always")
def logpdf_c(r: float, c) -> float:  # pragma: no cover - compiled
    """log f(r) with the `constants` c. For k = 1, where u > 8, Phi(u) is 1 to double
    precision and is not evaluated."""
    sigma, eps, inv_theta, shift, log_direct, log_delayed, _, shape = c
    z = r / sigma
    a = log_direct - 0.5 * z * z
    if eps == 0.0:
        return a
    u = z - shift
    if shape == 1:
        b = log_delayed - r * inv_theta + (log_ndtr(u) if u < 8.0 else 0.0)
    else:
        b = log_delayed - r * inv_theta + log_psi(u)
    return _log_add(a, b)


@njit(cache=True, nogil=True, inline="always")
def cdf_c(r: float, c) -> float:  # pragma: no cover - compiled
    """F(r) with the `constants` c; 0 below -40 sigma and its tail's closed form above."""
    sigma, eps, inv_theta, shift, _, _, half_shift2, shape = c
    z = r / sigma
    if z < -40.0:
        return 0.0
    gauss = ndtr(z) if z < 9.0 else 1.0
    if eps == 0.0:
        return gauss
    u = z - shift
    log_phi_u = log_ndtr(u) if u < 8.0 else 0.0
    if shape == 1:
        tail = math.exp(half_shift2 - r * inv_theta + log_phi_u)
    else:
        tail = math.exp(half_shift2 - r * inv_theta + _log_add(log_phi_u, math.log(shift) + log_psi(u)))
    return (1.0 - eps) * gauss + eps * (gauss - tail)


@njit(cache=True, nogil=True)
def toa_logpdf_kernel(r, sigma, eps, tau, shape, out):  # pragma: no cover - compiled
    """out[n] = log f(r[n]) over flat arrays, the constants computed once."""
    c = constants(sigma, eps, tau, shape)
    for n in range(r.shape[0]):
        out[n] = logpdf_c(r[n], c)


@njit(cache=True, nogil=True)
def toa_cdf_kernel(r, sigma, eps, tau, shape, out):  # pragma: no cover - compiled
    """out[n] = F(r[n]) over flat arrays, the constants computed once."""
    c = constants(sigma, eps, tau, shape)
    for n in range(r.shape[0]):
        out[n] = cdf_c(r[n], c)


@njit(cache=True, nogil=True, inline="always")
def detection_c(range_m: float, p_peak: float, half_range_km: float, falloff_km: float) -> float:  # pragma: no cover
    """Pd = p / (1 + exp((range - R) / w)) (`measurement.detection_prob`); R <= 0: no fall-off."""
    if half_range_km <= 0.0:
        return p_peak * 1.0
    z = (range_m / 1e3 - half_range_km) / falloff_km
    return p_peak * (1.0 / (1.0 + math.exp(z)))


@njit(cache=True, nogil=True)
def detection_kernel(ranges_m, p_peak, half_range_km, falloff_km, out):  # pragma: no cover - compiled
    """out (P, s) = `detection_c` of ranges (P, s) with beacon i's p_peak[i] and half_range_km[i]."""
    for p in range(ranges_m.shape[0]):
        for i in range(ranges_m.shape[1]):
            out[p, i] = detection_c(ranges_m[p, i], p_peak[i], half_range_km[i], falloff_km)


@njit(cache=True, nogil=True)
def factors_kernel(  # pragma: no cover - compiled
    mu, p_detect, toa, sigma, eps, tau, shape, log_lam, h, ranked, signal_term, log_match, log_unheard
):
    """log w_ij (P, s, K) and log u_i (P, s) of one window (module docstring): `toa`
    (1 or P, K) and the horizon `h` (1 or P,), one row shared by all particles, or one per
    particle (a batch of windows); `signal_term` (rows of `toa`, K), added to every
    log w_ij of signal j (e.g. the echo model's), or (0, K): none. Particle by particle
    (`_factors_row`)."""
    c = constants(sigma, eps, tau, shape)
    for p in range(mu.shape[0]):
        _factors_row(p, mu, p_detect, toa, sigma, eps, tau, log_lam, h, ranked, signal_term, c, log_match, log_unheard)


@njit(cache=True, nogil=True, parallel=True)
def factors_kernel_threaded(  # pragma: no cover - compiled
    mu, p_detect, toa, sigma, eps, tau, shape, log_lam, h, ranked, signal_term, log_match, log_unheard
):
    """`factors_kernel` on numba's threads (`model.parallel`)."""
    c = constants(sigma, eps, tau, shape)
    for q in prange(mu.shape[0]):
        p = np.intp(q)  # (one integer type: a prange index is unsigned)
        _factors_row(p, mu, p_detect, toa, sigma, eps, tau, log_lam, h, ranked, signal_term, c, log_match, log_unheard)


@njit(cache=True, nogil=True, inline="always")
def _factors_row(  # pragma: no cover - compiled
    p, mu, p_detect, toa, sigma, eps, tau, log_lam, h, ranked, signal_term, c, log_match, log_unheard
):
    """Particle p's log w_ij and log u_i (`factors_kernel`)."""
    s = mu.shape[1]
    k = toa.shape[1]
    row = 0 if toa.shape[0] == 1 else p
    added = signal_term.shape[0] > 0
    early = -FAR_EARLY * sigma
    late = FAR_LATE * tau if eps > 0.0 else FAR_LATE_DIRECT * sigma
    for i in range(s):
        log_pd = math.nan  # taken at the first signal within reach: most beacons have none
        for j in range(k):
            r = toa[row, j] - mu[p, i]
            if r < early or r > late:
                log_match[p, i, j] = -np.inf
                continue
            if math.isnan(log_pd):
                log_pd = math.log(p_detect[p, i])
            if added:
                log_match[p, i, j] = (log_pd + logpdf_c(r, c) - log_lam) + signal_term[row, j]
            else:
                log_match[p, i, j] = log_pd + logpdf_c(r, c) - log_lam
        if ranked:
            p_in = cdf_c(h[row] - mu[p, i], c) - cdf_c(-mu[p, i], c)
            log_unheard[p, i] = math.log1p(-p_detect[p, i] * min(max(p_in, 0.0), 1.0))
        else:
            log_unheard[p, i] = math.log1p(-p_detect[p, i])
