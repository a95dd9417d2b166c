"""Particle weights in log space, effective sample size, and resampling schemes.

Every scheme maps normalised weights W (N,) to N ancestor indices with E[copies of p] =
N W_p; they differ in variance (systematic and stratified are lower than multinomial;
residual copies floor(N W_p) deterministically). `RESAMPLERS` maps the config's
`[filter] resampling` to a scheme. Sums avoid BLAS, whose threaded reductions would make
results depend on the machine's thread count.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray
from scipy.special import logsumexp

Resampler = Callable[[NDArray, np.random.Generator], NDArray[np.intp]]


def normalise_log_weights(log_w: NDArray) -> tuple[NDArray[np.float64], float]:
    """Normalised weights W_p = exp(log_w_p - logsumexp(log_w)) and the log-sum."""
    log_sum = float(logsumexp(log_w))
    return np.exp(log_w - log_sum), log_sum


def ess(weights: NDArray) -> float:
    """Effective sample size 1 / sum W_p^2 of normalised weights."""
    return float(1.0 / np.einsum("p,p->", weights, weights))


def _inverse_cdf(weights: NDArray, points: NDArray) -> NDArray[np.intp]:
    """Indices p with C_{p-1} <= u < C_p for sorted points u in [0, 1)."""
    cumulative = np.cumsum(weights)
    cumulative[-1] = 1.0  # guard against round-off leaving the last point unmatched
    return np.searchsorted(cumulative, points, side="right")


def systematic(weights: NDArray, rng: np.random.Generator) -> NDArray[np.intp]:
    """Systematic resampling: one uniform U, points (U + k) / N, k = 0..N-1.

    Particle p is copied floor(N W_p) or ceil(N W_p) times.
    """
    n = len(weights)
    return _inverse_cdf(weights, (rng.random() + np.arange(n)) / n)


def stratified(weights: NDArray, rng: np.random.Generator) -> NDArray[np.intp]:
    """Stratified resampling: one uniform per stratum, points (U_k + k) / N."""
    n = len(weights)
    return _inverse_cdf(weights, (rng.random(n) + np.arange(n)) / n)


def multinomial(weights: NDArray, rng: np.random.Generator) -> NDArray[np.intp]:
    """Multinomial resampling: N independent draws from W (sorted uniforms)."""
    return _inverse_cdf(weights, np.sort(rng.random(len(weights))))


def residual(weights: NDArray, rng: np.random.Generator) -> NDArray[np.intp]:
    """Residual resampling: floor(N W_p) copies of p, the R remaining by multinomial
    draws from the residual weights N W_p - floor(N W_p)."""
    n = len(weights)
    scaled = n * np.asarray(weights, dtype=float)
    copies = np.floor(scaled).astype(np.intp)
    fixed = np.repeat(np.arange(n), copies)
    remaining = n - len(fixed)
    if remaining == 0:
        return fixed
    rest = scaled - copies
    extra = _inverse_cdf(rest / rest.sum(), np.sort(rng.random(remaining)))
    return np.sort(np.concatenate([fixed, extra]))


RESAMPLERS: dict[str, Resampler] = {
    "systematic": systematic,
    "stratified": stratified,
    "residual": residual,
    "multinomial": multinomial,
}
