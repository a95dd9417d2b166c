"""Geodesy against GeographicLib (Karney's algorithms), an independent implementation."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from geographiclib.geodesic import Geodesic

from rafostrack.model.geodesy import (
    EXPANSION_TOLERANCE_M,
    MIN_EXPANDED,
    displace,
    local_offsets_km,
    range_m,
    range_matrix_m,
    range_of_terms_m,
    ranges_about_centre_m,
    stacked_point_terms,
    wrap_lon,
)


def test_ranges_match_geographiclib_within_10m_up_to_3000km():
    rng = np.random.default_rng(42)
    cases = []
    for lat0 in (-75.0, -60.0, -30.0, 0.0, 30.0, 60.0, 75.0):
        for _ in range(150):
            lat1, lon1 = lat0 + rng.uniform(-3, 3), rng.uniform(-180, 180)
            d = Geodesic.WGS84.Direct(lat1, lon1, rng.uniform(0, 360), rng.uniform(0.0, 3000e3))
            cases.append((lat1, lon1, d["lat2"], d["lon2"], d["s12"]))
    lat1, lon1, lat2, lon2, truth = np.array(cases).T
    err = np.abs(range_m(lat1, lon1, lat2, lon2) - truth)
    assert err.max() < 10.0


def test_range_is_symmetric_and_zero_at_a_point():
    assert range_m(-58.0, -100.0, -58.0, -100.0) == 0.0
    a = range_m(-58.0, -100.0, -60.0, -80.0)
    assert a == pytest.approx(range_m(-60.0, -80.0, -58.0, -100.0), rel=1e-12)
    assert np.isnan(range_m(0.0, 0.0, 0.0, 180.0))  # antipodal: outside the formula's domain


def test_missing_and_coincident_positions_without_a_warning():
    """A missing position has a missing range, a point its own range 0, among many pairs
    (the compiled loop is vectorised: no edge case may raise a floating-point warning)."""
    lat = np.linspace(-60.0, -55.0, 64)
    lon = np.linspace(-100.0, -90.0, 64)
    lat[::7] = np.nan
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        r = range_m(lat, lon, lat, lon)
    assert np.all(np.isnan(r[::7]))
    assert np.all(np.delete(r, np.arange(0, 64, 7)) == 0.0)


def test_range_broadcasts_particles_against_beacons():
    lat = np.array([-58.0, -57.0, -56.0])[:, None]
    lon = np.array([-100.0, -99.0, -98.0])[:, None]
    out = range_m(lat, lon, np.array([-60.0, -55.0]), np.array([-90.0, -95.0]))
    assert out.shape == (3, 2)


def test_range_matrix_is_range_m_of_the_outer_pairs_bit_for_bit():
    """Particles x beacons in one compiled loop: the numbers of the broadcast `range_m`,
    edge cases included (a missing particle, a particle on a beacon, an antipode)."""
    rng = np.random.default_rng(3)
    lat, lon = rng.uniform(-70.0, -50.0, 257), rng.uniform(-70.0, 20.0, 257)
    beacon_lat, beacon_lon = rng.uniform(-70.0, -50.0, 7), rng.uniform(-70.0, 20.0, 7)
    lat[5] = np.nan
    beacon_lat[2], beacon_lon[2] = lat[9], lon[9]
    beacon_lat[4], beacon_lon[4] = -lat[11], lon[11] + 180.0
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out = range_matrix_m(lat, lon, beacon_lat, beacon_lon)
    expected = range_m(lat[:, None], lon[:, None], beacon_lat[None, :], beacon_lon[None, :])
    assert out.shape == (257, 7)
    np.testing.assert_array_equal(out, expected)
    assert out[9, 2] == 0.0 and np.isnan(out[11, 4]) and np.isnan(out[5]).all()


def test_ranges_of_point_terms_taken_by_index_are_range_m_bit_for_bit():
    """Terms computed once per point (nodes, sources) and taken per pair by an index give
    the numbers `range_m` gives on the pairs themselves (the Kalman fit's arrival ranges)."""
    rng = np.random.default_rng(4)
    lat, lon = rng.uniform(-70.0, -50.0, 301), rng.uniform(-70.0, 20.0, 301)
    source_lat, source_lon = rng.uniform(-70.0, -50.0, 9), rng.uniform(-70.0, 20.0, 9)
    node, source = rng.integers(0, 301, 2000), rng.integers(0, 9, 2000)
    out = range_of_terms_m(
        stacked_point_terms(lat, lon)[:, node], stacked_point_terms(source_lat, source_lon)[:, source]
    )
    np.testing.assert_array_equal(out, range_m(lat[node], lon[node], source_lat[source], source_lon[source]))


def test_displace_and_offsets_round_trip():
    lat, lon = np.array([-58.0, 10.0]), np.array([179.5, -20.0])
    new_lat, new_lon = displace(lat, lon, np.array([40.0, -3.0]), np.array([-25.0, 7.0]))
    assert -180 <= new_lon[0] < 180  # crossed the antimeridian
    for k in range(2):
        east, north = local_offsets_km(new_lat[k], new_lon[k], lat[k], lon[k])
        assert float(east) == pytest.approx([40.0, -3.0][k], abs=0.05)
        assert float(north) == pytest.approx([-25.0, 7.0][k], abs=0.05)
    # Small displacements agree with the geodesic distance.
    d = range_m(lat[1], lon[1], new_lat[1], new_lon[1])
    assert d == pytest.approx(np.hypot(3e3, 7e3), rel=1e-3)


def test_wrap_lon():
    assert np.allclose(wrap_lon([180.0, -180.0, 190.0, 359.0, -181.0]), [-180.0, -180.0, -170.0, -1.0, 179.0])
    assert np.allclose(wrap_lon([-180.0, 0.1, 179.9]), [-180.0, 0.1, 179.9])  # all in range: no remainder taken
    assert wrap_lon(540.0) == -180.0 and wrap_lon(-10.0) == pytest.approx(-10.0)


def test_ranges_about_a_centre_are_within_the_tolerance_of_the_exact_formula_and_geographiclib():
    """The expansion about a cloud's centre (`ranges_about_centre_m`): within
    `EXPANSION_TOLERANCE_M` of the exact formula for clouds of 1-100 km sd at latitudes up
    to 75 degrees and far points 20-2500 km away, and within that plus the formula's own
    10 m of GeographicLib; a handful of points take the exact formula itself."""
    rng = np.random.default_rng(5)
    worst_exact, worst_karney = 0.0, 0.0
    for _ in range(60):
        lat0, lon0, sd = rng.uniform(-75, 75), rng.uniform(-180, 180), rng.choice([1.0, 5.0, 20.0, 100.0])
        lat, lon = displace(np.full(500, lat0), np.full(500, lon0), rng.normal(0, sd, 500), rng.normal(0, sd, 500))
        bearing, distance = rng.uniform(0, 360, 6), rng.uniform(20e3, 2500e3, 6)
        far = [Geodesic.WGS84.Direct(lat0, lon0, b, d) for b, d in zip(bearing, distance, strict=True)]
        far_lat, far_lon = np.array([f["lat2"] for f in far]), np.array([f["lon2"] for f in far])
        expanded = ranges_about_centre_m(lat, lon, far_lat, far_lon)
        worst_exact = max(worst_exact, float(np.abs(expanded - range_matrix_m(lat, lon, far_lat, far_lon)).max()))
        for p in rng.choice(500, 5, replace=False):
            for i in range(6):
                karney = Geodesic.WGS84.Inverse(lat[p], lon[p], far_lat[i], far_lon[i])["s12"]
                worst_karney = max(worst_karney, abs(expanded[p, i] - karney))
    assert worst_exact < EXPANSION_TOLERANCE_M and worst_karney < EXPANSION_TOLERANCE_M + 10.0
    few = ranges_about_centre_m(lat[: MIN_EXPANDED - 1], lon[: MIN_EXPANDED - 1], far_lat, far_lon)
    assert np.array_equal(few, range_matrix_m(lat[: MIN_EXPANDED - 1], lon[: MIN_EXPANDED - 1], far_lat, far_lon))
