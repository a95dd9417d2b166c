"""Float drift between windows: an isotropic random walk (paper eq. 1).

X_{t+dt} = X_t + (e, n),  e, n ~ N(0, D^2 dt)  with D = diffusion_km_per_day and dt in
days, applied in the local east/north tangent plane of each particle.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .geodesy import displace


def scatter(
    lat: NDArray, lon: NDArray, sd_km: float, rng: np.random.Generator
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Move each point by independent N(0, sd_km^2) east and north displacements."""
    east, north = rng.normal(0.0, sd_km, size=(2, len(lat)))
    new_lat, new_lon = displace(lat, lon, east, north)
    return np.clip(new_lat, -89.999, 89.999), new_lon


def propagate(
    lat: NDArray, lon: NDArray, dt_days: float, diffusion_km_per_day: float, rng: np.random.Generator
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Random-walk step over `dt_days`: per-axis sd = diffusion * sqrt(dt_days)."""
    return scatter(lat, lon, diffusion_km_per_day * np.sqrt(max(dt_days, 0.0)), rng)
