"""Detection per beacon, estimated from a first pass: how often a beacon was heard, by range.

For each window and each active beacon whose predicted arrival falls well inside what the
window could store (before the horizon, by 3 sd), the beacon was heard or not (a signal
of the window carries its label with probability >= 0.5). The model's detection
probability p / (1 + exp((range - R) / w)) (`model.measurement.detection_prob`, w the configured
fall-off width) is fitted per beacon by maximum likelihood of those Bernoulli outcomes,
p within `P_BOUNDS` and R within `RANGE_BOUNDS_KM`. A beacon with too few opportunities
keeps the configured values.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize
from scipy.special import expit, logit

MIN_OPPORTUNITIES = 30
P_BOUNDS = (0.05, 0.995)
RANGE_BOUNDS_KM = (50.0, 5000.0)


def heard_nowhere(p_detect: float) -> bool:
    """Whether a fitted peak probability is at its lower bound: the fit's way of saying the
    beacon is heard nowhere (no arrival, or only a few, carried its label), so that the
    tracker will call its arrivals clutter: right for a source out of range, wrong for one
    whose few arrivals a pass called clutter (docs/decisions.md)."""
    return p_detect <= P_BOUNDS[0]


def fit_detection(
    range_km: NDArray, heard: NDArray, falloff_km: float, p0: float, r0_km: float
) -> tuple[float, float] | None:
    """(p, R) for one beacon from its opportunities (range, heard in [0, 1]), or None."""
    if len(range_km) < MIN_OPPORTUNITIES:
        return None
    h = np.clip(heard, 0.0, 1.0)

    def unpack(q: NDArray) -> tuple[float, float]:
        return float(np.clip(expit(q[0]), *P_BOUNDS)), float(np.clip(np.exp(q[1]), *RANGE_BOUNDS_KM))

    def cost(q: NDArray) -> float:
        p, r50 = unpack(q)
        pd = np.clip(p * expit(-(range_km - r50) / falloff_km), 1e-9, 1 - 1e-9)
        return -float(np.sum(h * np.log(pd) + (1 - h) * np.log1p(-pd)))

    start = np.array([logit(min(max(p0, 0.1), 0.99)), np.log(r0_km if r0_km > 0 else 1500.0)])
    best = minimize(cost, start, method="Nelder-Mead", options={"xatol": 1e-4, "fatol": 1e-6, "maxiter": 1000})
    return unpack(best.x)
