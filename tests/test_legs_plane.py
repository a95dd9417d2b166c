"""The mission plane: an exact inverse, distances and local scales."""

from __future__ import annotations

import numpy as np

from rafostrack.legs.plane import Plane
from rafostrack.model.geodesy import local_offsets_km, range_m


def test_round_trip_and_distances_from_the_centre():
    plane = Plane(-57.0, 179.5)
    rng = np.random.default_rng(0)
    lat = -57.0 + rng.uniform(-6, 6, 200)
    lon = 179.5 + rng.uniform(-12, 12, 200)
    xy = plane.to_plane(lat, lon)
    back_lat, back_lon = plane.from_plane(xy)
    np.testing.assert_allclose(back_lat, lat, atol=1e-9)
    np.testing.assert_allclose((back_lon - lon + 180) % 360 - 180, 0, atol=1e-9)
    dist = range_m(plane.lat0, plane.lon0, lat, lon) / 1e3
    np.testing.assert_allclose(np.hypot(xy[:, 0], xy[:, 1]), dist, rtol=4e-3)


def test_local_scales_are_exact_at_the_centre():
    plane = Plane(-60.0, -40.0)
    lat, lon = np.array([-60.0, -60.01, -59.99]), np.array([-40.01, -40.0, -39.99])
    east, north = local_offsets_km(lat, lon, plane.lat0, plane.lon0)
    np.testing.assert_allclose(plane.to_plane(lat, lon), np.column_stack([east, north]), rtol=5e-4, atol=1e-3)
