"""Correlation height as evidence of source vs clutter.

A RAFOS float stores, with each arrival time, the height of the correlation peak that
detected it (Argo's `COR`, our `quality`). A source's signal correlates well with the
replica, a noise spike less so. With class-conditional densities f_s (from a source) and
f_c (clutter) of the height q, a stored signal j carries the likelihood ratio

    r_j = f_s(q_j) / f_c(q_j),     here f = Gaussian:  log r_j = log N(q_j; mu_s, sd_s) - log N(q_j; mu_c, sd_c)

which multiplies every association term that explains signal j by a source (the matched
factor w_ij of docs/method.md) against the terms calling it clutter. log r_j is
capped at +-`max_abs_log_ratio` (the Gaussian tails are not to be trusted far out) and is 0
for a signal without a height, or when the feature is off: the model is then unchanged.

In the association factors (`model.measurement.association_factors`, `source_log_ratio`), the log match
weight of signal j for every beacon i, log w_ij, gets + log r_j (and an echo's term likewise).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..config import QualityConfig

_LOG_SQRT_2PI = 0.5 * np.log(2.0 * np.pi)


def _log_normal(q: NDArray[np.float64], mean: float, sd: float) -> NDArray[np.float64]:
    z = (q - mean) / sd
    return -0.5 * z * z - np.log(sd) - _LOG_SQRT_2PI


def quality_log_ratio(quality: ArrayLike, config: QualityConfig) -> NDArray[np.float64]:
    """Per signal, log f_s(q) - log f_c(q) (module docstring), capped; 0 where q is missing
    (NaN) or the feature is off. Vectorised over any array shape."""
    q = np.asarray(quality, dtype=float)
    if not config.enabled:
        return np.zeros(q.shape)
    ratio = _log_normal(q, config.source_mean, config.source_sd) - _log_normal(
        q, config.clutter_mean, config.clutter_sd
    )
    ratio = np.clip(ratio, -config.max_abs_log_ratio, config.max_abs_log_ratio)
    return np.where(np.isfinite(q), ratio, 0.0)


@dataclass(frozen=True)
class QualityFit:
    source_mean: float
    source_sd: float
    clutter_mean: float
    clutter_sd: float
    n_source: int
    n_clutter: int


def fit_quality(quality: ArrayLike, is_source: ArrayLike, min_per_class: int = 20) -> QualityFit | None:
    """The class-conditional Gaussians from labelled heights (e.g. hand labels, or confident
    labels of a first pass): each class's mean and sd. None when a class has fewer than
    `min_per_class` heights (then keep the configured values)."""
    q = np.asarray(quality, dtype=float)
    src = np.asarray(is_source, dtype=bool)
    ok = np.isfinite(q)
    a, b = q[ok & src], q[ok & ~src]
    if len(a) < min_per_class or len(b) < min_per_class:
        return None
    return QualityFit(float(a.mean()), float(a.std(ddof=1)), float(b.mean()), float(b.std(ddof=1)), len(a), len(b))
