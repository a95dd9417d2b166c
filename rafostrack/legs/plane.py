"""A plane for a float's legs: azimuthal equidistant about a centre, local scales exact there.

Straight legs at constant speed need a plane in kilometres over the whole mission (a
2-year float spans ~1000 km, where a tangent plane's east scale is off by ~10%). On the
unit sphere, with c the angular distance from the centre (lat0, lon0) and k = c / sin c,
    e = k cos(lat) sin(dlon),  n = k (cos lat0 sin lat - sin lat0 cos lat cos dlon),
scaled by the ellipsoid's radii of curvature at the centre: x = N e, y = M n (km). At the
centre the local east and north scales are exact; 1000 km away the distortion is a few
tenths of a percent, and positions are always turned back into latitude and longitude
(`from_plane`, the exact inverse) before any range is computed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..model.geodesy import radii_of_curvature_m, wrap_lon


@dataclass(frozen=True)
class Plane:
    lat0: float
    lon0: float

    @property
    def scales_km(self) -> tuple[float, float]:
        m, n = radii_of_curvature_m(self.lat0)
        return float(n) / 1e3, float(m) / 1e3

    def to_plane(self, lat: ArrayLike, lon: ArrayLike) -> NDArray[np.float64]:
        """(..., 2) east/north km of points given in degrees."""
        phi, phi0 = np.radians(np.asarray(lat, dtype=float)), np.radians(self.lat0)
        dlon = np.radians(wrap_lon(np.asarray(lon, dtype=float) - self.lon0))
        cos_c = np.clip(np.sin(phi0) * np.sin(phi) + np.cos(phi0) * np.cos(phi) * np.cos(dlon), -1.0, 1.0)
        c = np.arccos(cos_c)
        with np.errstate(invalid="ignore", divide="ignore"):
            k = np.where(c > 1e-12, c / np.sin(c), 1.0)
        e = k * np.cos(phi) * np.sin(dlon)
        n = k * (np.cos(phi0) * np.sin(phi) - np.sin(phi0) * np.cos(phi) * np.cos(dlon))
        sx, sy = self.scales_km
        return np.stack([sx * e, sy * n], axis=-1)

    def from_plane(self, xy: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Latitude and longitude (degrees) of plane points (..., 2), the inverse of `to_plane`."""
        xy = np.asarray(xy, dtype=float)
        sx, sy = self.scales_km
        e, n = xy[..., 0] / sx, xy[..., 1] / sy
        rho = np.hypot(e, n)
        phi0 = np.radians(self.lat0)
        sin_c, cos_c = np.sin(rho), np.cos(rho)
        with np.errstate(invalid="ignore", divide="ignore"):
            ratio = np.where(rho > 1e-15, n * sin_c / rho, n)
        phi = np.arcsin(np.clip(cos_c * np.sin(phi0) + ratio * np.cos(phi0), -1.0, 1.0))
        dlon = np.arctan2(e * np.where(rho > 1e-15, sin_c / np.where(rho > 1e-15, rho, 1.0), 1.0),
                          cos_c * np.cos(phi0) - ratio * np.sin(phi0))  # fmt: skip
        return np.degrees(phi), wrap_lon(self.lon0 + np.degrees(dlon))
