"""Position fixes as observations: a Gaussian position measurement in the fix's tangent plane.

    log p(fix | X) = log N(X - fix; 0, sd^2 I) = -|d|^2 / (2 sd^2) - log(2 pi sd^2),

with d the east/north offset (km) of the particle from the fix. The launch fix is the
filter's prior; the end (surfacing) fix is this observation at `end_time`, so a smoothed
track is pinned at both ends. A fix more than OUTLIER_SD sd from every particle has its sd
widened (with a warning) rather than collapsing the cloud onto one particle.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..domain import Particles, PositionFix
from ..errors import Notice, WarningKind
from ..model.geodesy import local_offsets_km
from .base import Evidence, Likelihood, outlier_scale


def fix_loglik(lat: NDArray, lon: NDArray, fix_lat: float, fix_lon: float, sd_km: float) -> NDArray:
    """log N(X - fix; 0, sd^2 I) of a position fix, in the fix's tangent plane."""
    east, north = local_offsets_km(lat, lon, fix_lat, fix_lon)
    return -(east * east + north * north) / (2.0 * sd_km * sd_km) - np.log(2.0 * np.pi * sd_km * sd_km)


def fix_distances_km(lat: NDArray, lon: NDArray, fix_lat: float, fix_lon: float) -> NDArray:
    east, north = local_offsets_km(lat, lon, fix_lat, fix_lon)
    return np.hypot(east, north)


class PositionFixLikelihood(Likelihood):
    """A GPS fix of the float (its sd from the fix itself)."""

    def __init__(self, float_id: str):
        self.float_id = float_id

    def evaluate(self, particles: Particles, observation: PositionFix, *, marginals: bool = True) -> Evidence:
        fix = observation
        nearest = float(fix_distances_km(particles.lat, particles.lon, fix.lat, fix.lon).min())
        scale = float(outlier_scale(nearest / fix.sd_km))
        warnings: tuple[str, ...] = ()
        if scale > 1.0:
            warnings = (
                Notice(
                    WarningKind.END_FIX,
                    f"{self.float_id}: the end fix is {nearest:.1f} km from every particle "
                    f"({nearest / fix.sd_km:.0f} sd); its sd was widened to {fix.sd_km * scale:.1f} km",
                ),
            )
        loglik = fix_loglik(particles.lat, particles.lon, fix.lat, fix.lon, fix.sd_km * scale)
        return Evidence(loglik, warnings=warnings)
