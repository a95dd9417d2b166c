"""Drift statistics of a track: mean current, eddy velocity sd and decorrelation time.

The single-particle dispersion of Lagrangian floats (Taylor 1921; LaCasce 2008, "Statistics
from Lagrangian observations"): for an integrated Ornstein-Uhlenbeck velocity (sd sigma,
time scale T, `motion.IntegratedOU`), the mean velocity over a span of k days, after the
mean current is removed, has per-axis variance

    V(k) = sigma^2 g(k / T),   g(d) = 2 (d - 1 + e^-d) / d^2,

to which position errors of sd e add 2 e^2 / k^2. The mean current is the track's overall
displacement over its duration; (sigma, T, e) are fitted to the empirical V(k) of the
first-pass track for k = 1..20 days (least squares on log V, each k weighted by how many
spans it has), sigma in [1, 20] km/day, T in [2, 30] days (a shorter time scale cannot be told
from position errors by daily positions).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from numpy.typing import NDArray
from scipy.optimize import least_squares

from ..domain import elapsed_days
from ..geodesy import local_offsets_km

MAX_LAG_DAYS = 20
MIN_DAYS = 30.0


def _structure(d: NDArray) -> NDArray:
    """g(d) = 2 (d - 1 + e^-d) / d^2, with its series for small d."""
    d = np.asarray(d, dtype=float)
    small = d < 1e-3
    out = np.empty_like(d)
    out[~small] = 2.0 * (d[~small] - 1.0 + np.exp(-d[~small])) / d[~small] ** 2
    out[small] = 1.0 - d[small] / 3.0
    return out


def fit_drift(track: pd.DataFrame) -> tuple[NDArray[np.float64], float, float] | None:
    """(mean current east/north km/day, sigma km/day, T days) of a track (time, lat, lon), or
    None when it is shorter than MIN_DAYS."""
    times = track["time"].to_numpy(dtype="datetime64[ns]")
    days = elapsed_days(times, times[0])
    if len(days) < 10 or days[-1] < MIN_DAYS:
        return None
    lat0, lon0 = float(track["lat"].iloc[0]), float(track["lon"].iloc[0])
    east, north = local_offsets_km(track["lat"].to_numpy(), track["lon"].to_numpy(), lat0, lon0)
    mean = np.array([east[-1] - east[0], north[-1] - north[0]]) / (days[-1] - days[0])
    xe, xn = east - mean[0] * days, north - mean[1] * days
    lags, variances, counts = [], [], []
    for k in range(1, MAX_LAG_DAYS + 1):
        j = np.searchsorted(days, days + k)
        ok = (j < len(days)) & (np.abs(days[np.minimum(j, len(days) - 1)] - days - k) < 0.25)
        if ok.sum() < 10:
            continue
        span = days[j[ok]] - days[ok]
        ve, vn = (xe[j[ok]] - xe[ok]) / span, (xn[j[ok]] - xn[ok]) / span
        lags.append(k)
        variances.append(0.5 * (np.var(ve) + np.var(vn)))
        counts.append(int(ok.sum()))
    if len(lags) < 5:
        return None
    lag, var, weight = np.array(lags, float), np.array(variances), np.sqrt(np.array(counts, float))

    def residual(q: NDArray) -> NDArray:
        sigma, timescale, err = np.exp(q)
        model = sigma**2 * _structure(lag / timescale) + 2.0 * err**2 / lag**2
        return weight * (np.log(model) - np.log(var))

    lower, upper = np.array([1.0, 2.0, 0.01]), np.array([20.0, 30.0, 20.0])
    start = np.clip([np.sqrt(var[0]), 5.0, 1.0], lower * 1.001, upper * 0.999)  # inside the bounds
    fit = least_squares(residual, np.log(start), bounds=(np.log(lower), np.log(upper)))
    sigma, timescale, _ = np.exp(fit.x)
    return mean, float(sigma), float(timescale)
