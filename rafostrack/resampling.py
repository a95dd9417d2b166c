"""Particle weights in log space, effective sample size and systematic resampling."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.special import logsumexp


def normalise_log_weights(log_w: NDArray) -> tuple[NDArray[np.float64], float]:
    """Normalised weights W_p = exp(log_w_p - logsumexp(log_w)) and the log-sum."""
    log_sum = float(logsumexp(log_w))
    return np.exp(log_w - log_sum), log_sum


def ess(weights: NDArray) -> float:
    """Effective sample size 1 / sum W_p^2 of normalised weights."""
    return float(1.0 / np.einsum("p,p->", weights, weights))  # no BLAS: thread-count independent


def systematic(weights: NDArray, rng: np.random.Generator) -> NDArray[np.intp]:
    """Systematic resampling: one uniform U, points (U + k) / N, k = 0..N-1.

    Particle p is copied floor(N W_p) or ceil(N W_p) times.
    """
    n = len(weights)
    points = (rng.random() + np.arange(n)) / n
    cumulative = np.cumsum(weights)
    cumulative[-1] = 1.0  # guard against round-off leaving the last point unmatched
    return np.searchsorted(cumulative, points, side="right")
