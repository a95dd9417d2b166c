"""Distances and local displacements on the WGS84 ellipsoid, vectorised over arrays.

Ranges use the Andoyer-Lambert formula: a closed form with no iteration, within a few
metres of the exact geodesic over the few thousand kilometres of an acoustic array
(about 4x faster than iterating Vincenty's formulae). A sphere would be off by up to
~4 km at 1000 km, more than the arrival-time noise.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange, vectorize
from numpy.typing import ArrayLike, NDArray

from .parallel import threaded

WGS84_A_M = 6378137.0
WGS84_F = 1.0 / 298.257223563
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)


def range_m(lat1: ArrayLike, lon1: ArrayLike, lat2: ArrayLike, lon2: ArrayLike) -> NDArray:
    """Geodesic distance (m) between points given in degrees; inputs broadcast.

    Andoyer-Lambert: with reduced latitudes beta_k = atan((1 - f) tan phi_k), central angle
    sigma between (beta_1, lambda_1) and (beta_2, lambda_2) on the auxiliary sphere,
    P = (beta_1 + beta_2)/2 and Q = (beta_2 - beta_1)/2,
        X = (sigma - sin sigma) sin^2 P cos^2 Q / cos^2(sigma/2)
        Y = (sigma + sin sigma) cos^2 P sin^2 Q / sin^2(sigma/2)
        s = a (sigma - f/2 (X + Y)).
    Error O(f^2): under 5 m up to 3000 km (tests/test_geodesy.py checks it against
    GeographicLib).
    """
    # Trigonometric terms of each point (cheap: the inputs before broadcasting), so that a
    # pair costs one arcsin and two square roots (`_pair_range_m`, compiled: one pass over
    # the pairs, no temporaries).
    b1, half_b1, half_l1 = _point_terms(lat1, lon1)
    b2, half_b2, half_l2 = _point_terms(lat2, lon2)
    return _pair_range_m(*b1, *half_b1, *half_l1, *b2, *half_b2, *half_l2)


def range_matrix_m(lat1: ArrayLike, lon1: ArrayLike, lat2: ArrayLike, lon2: ArrayLike) -> NDArray:
    """Ranges (m) from each of n points (lat1, lon1) to each of m points (lat2, lon2), (n, m):
    `range_m` of the outer pairs, the same numbers, in one compiled loop over the pairs (e.g.
    particles x beacons) rather than a broadcast of twelve operands."""
    first, second = stacked_point_terms(lat1, lon1), stacked_point_terms(lat2, lon2)
    out = np.empty((first.shape[1], second.shape[1]))
    _range_matrix_m(first, second, out)
    return out


@njit(cache=True, nogil=True)
def _range_matrix_m(first, second, out):  # pragma: no cover - compiled
    """out[p, i] = `_andoyer_m` of point terms (6, n) column p and (6, m) column i."""
    for p in range(first.shape[1]):
        exact_ranges_row(first, p, second, out[p])


@njit(cache=True, nogil=True, inline="always")
def exact_ranges_row(first, p, second, row):  # pragma: no cover - compiled
    """row[i] = `_andoyer_m` of point terms (6, n) column p and (6, m) column i."""
    for i in range(second.shape[1]):
        row[i] = _andoyer_m(
            first[0, p], first[1, p], first[2, p], first[3, p], first[4, p], first[5, p],
            second[0, i], second[1, i], second[2, i], second[3, i], second[4, i], second[5, i],
        )  # fmt: skip


@njit(cache=True, nogil=True)
def _andoyer_m(sb1, cb1, shb1, chb1, shl1, chl1, sb2, cb2, shb2, chb2, shl2, chl2):  # pragma: no cover
    """Andoyer-Lambert (`range_m`) from each point's (sin b, cos b), (sin b/2, cos b/2),
    (sin lambda/2, cos lambda/2). With P = (b1 + b2)/2, Q = (b2 - b1)/2: sin P cos Q =
    (sin b1 + sin b2)/2, cos P sin Q = (sin b2 - sin b1)/2, sin^2(sigma/2) = h, cos^2(sigma/2)
    = 1 - h, sin sigma = 2 sqrt(h (1 - h)); the half-angle differences by the subtraction
    formula (absolute error ~1e-16: metres are unaffected), h by the haversine (well
    conditioned at short range)."""
    sin_half_db = shb2 * chb1 - chb2 * shb1
    sin_half_dl = shl2 * chl1 - chl2 * shl1
    h = sin_half_db * sin_half_db + cb1 * cb2 * sin_half_dl * sin_half_dl
    # The loop over pairs may be vectorised, so every branch is evaluated for every pair: no
    # expression may divide by zero or order-compare a NaN (either raises the invalid flag,
    # a RuntimeWarning). Edge cases are computed with h = 1/2 and chosen at the end.
    missing = math.isnan(h)  # a missing position
    h = min(max(0.5 if missing else h, 0.0), 1.0)
    coincident, antipodal = h == 0.0, h == 1.0  # Y would be 0/0; X x/0 (outside the domain)
    if coincident or antipodal:
        h = 0.5
    sigma = 2.0 * math.asin(math.sqrt(h))
    sin_sigma = 2.0 * math.sqrt(h * (1.0 - h))
    x = (sigma - sin_sigma) * (0.5 * (sb1 + sb2)) ** 2 / (1.0 - h)
    y = (sigma + sin_sigma) * (0.5 * (sb2 - sb1)) ** 2 / h
    if missing or antipodal:
        return math.nan
    if coincident:
        return 0.0
    return WGS84_A_M * (sigma - WGS84_F / 2.0 * (x + y))


@vectorize([f"float64({', '.join(['float64'] * 12)})"], cache=True)
def _pair_range_m(sb1, cb1, shb1, chb1, shl1, chl1, sb2, cb2, shb2, chb2, shl2, chl2):  # pragma: no cover
    """`_andoyer_m` as a numpy ufunc (broadcasting its operands)."""
    return _andoyer_m(sb1, cb1, shb1, chb1, shl1, chl1, sb2, cb2, shb2, chb2, shl2, chl2)


def _point_terms(lat_deg: ArrayLike, lon_deg: ArrayLike) -> tuple[tuple[NDArray, NDArray], ...]:
    """(sin b, cos b), (sin b/2, cos b/2), (sin lambda/2, cos lambda/2) of points, b the
    reduced latitude atan((1 - f) tan phi)."""
    b = np.arctan((1.0 - WGS84_F) * np.tan(np.radians(np.asarray(lat_deg, dtype=float))))
    half_lon = np.radians(np.asarray(lon_deg, dtype=float)) / 2.0
    return (np.sin(b), np.cos(b)), (np.sin(b / 2.0), np.cos(b / 2.0)), (np.sin(half_lon), np.cos(half_lon))


def stacked_point_terms(lat_deg: ArrayLike, lon_deg: ArrayLike) -> NDArray[np.float64]:
    """`_point_terms` of points (flattened) as one (6, n) array, in `_andoyer_m`'s order."""
    return np.array([t for pair in _point_terms(np.ravel(lat_deg), np.ravel(lon_deg)) for t in pair])


def range_of_terms_m(first: NDArray, second: NDArray) -> NDArray:
    """`range_m` between points given by their terms (`stacked_point_terms`, (6, n) each):
    the same numbers, for points whose terms serve several ranges (computed once per point,
    and taken for each pair by indexing, the terms being elementwise)."""
    return _pair_range_m(*first, *second)


# Ranges about a centre (`ranges_about_centre_m`): a pair's error bound, |d|^3 (0.25 / (R0 -
# |d|)^2 + (1 + tan^2 lat0) / a^2) (|d| the point's distance from the centre, R0 the centre's
# range, a the Earth's radius: the third directional derivative of a distance is at most
# 2 / sqrt(3) / r^2, the Taylor remainder 1/6 of it; the second term bounds what the
# curvature of the (lat, lon) grid adds), held under this; the exact formula elsewhere.
EXPANSION_TOLERANCE_M = 10.0
EXPANSION_STEP_KM = 1.0  # the finite differences' step
MIN_EXPANDED = 64  # fewer points: the exact formula for every pair


def ranges_about_centre_m(lat: ArrayLike, lon: ArrayLike, lat_b: ArrayLike, lon_b: ArrayLike) -> NDArray:
    """Ranges (m) from n points (lat, lon), a cloud, to m far points (lat_b, lon_b), (n, m):
    `range_matrix_m`'s to within `EXPANSION_TOLERANCE_M`, cheaper. About the cloud's centre
    (its mean point), each range is a second-order expansion in (lat, lon),

        R(x) = R0 + g . d + d' H d / 2,    d = (lat - lat0, lon - lon0) in degrees,

    its gradient and Hessian from the exact ranges at nine points `EXPANSION_STEP_KM` apart
    about the centre (`_expansion`); a pair whose error bound (`EXPANSION_TOLERANCE_M`'s
    comment) exceeds the tolerance (a point far from the centre, or near the far point)
    gets the exact formula. Fewer than `MIN_EXPANDED` points: `range_matrix_m` itself."""
    lat, lon = np.ravel(np.asarray(lat, dtype=np.float64)), np.ravel(np.asarray(lon, dtype=np.float64))
    lat_b, lon_b = np.ravel(np.asarray(lat_b, dtype=np.float64)), np.ravel(np.asarray(lon_b, dtype=np.float64))
    if not expands_about_centre(lat, lon):
        return range_matrix_m(lat, lon, lat_b, lon_b)
    centre, coef, far_terms = _expansion(lat, lon, lat_b, lon_b, EXPANSION_STEP_KM)
    out = np.empty((len(lat), len(lat_b)))
    kernel = _expanded_ranges_threaded_m if threaded(len(lat)) else _expanded_ranges_m
    kernel(lat, lon, centre, coef, far_terms, EXPANSION_TOLERANCE_M / 1e3, out)
    return out


def expands_about_centre(lat: NDArray, lon: NDArray) -> bool:
    """Whether `ranges_about_centre_m` expands the ranges of the points (lat, lon) about their
    centre: `MIN_EXPANDED` points or more, all finite (else the exact formula)."""
    return len(lat) >= MIN_EXPANDED and bool(np.all(np.isfinite(lat) & np.isfinite(lon)))


@njit(cache=True, nogil=True)
def _expansion(lat, lon, lat_b, lon_b, step_km):  # pragma: no cover - compiled
    """The cloud's centre and scales, (lat0, lon0, km per degree of lat and of lon, a^2 /
    (1 + tan^2 lat0) in km^2), the expansion's coefficients (m, 6): R0, dR/dlat, dR/dlon,
    d2R/dlat2, d2R/dlat dlon, d2R/dlon2 (m; degrees) by central differences of `step_km`
    of the exact ranges, and the far points' terms (6, m) for `_andoyer_m`."""
    n, m = lat.shape[0], lat_b.shape[0]
    lat0 = 0.0
    shift = 0.0
    for p in range(n):
        lat0 += lat[p]
        dx = lon[p] - lon[0]
        shift += dx - 360.0 if dx >= 180.0 else (dx + 360.0 if dx < -180.0 else dx)
    lat0 /= n
    lon0 = lon[0] + shift / n
    lon0 = lon0 - 360.0 if lon0 >= 180.0 else (lon0 + 360.0 if lon0 < -180.0 else lon0)
    phi = math.radians(lat0)
    w = math.sqrt(1.0 - WGS84_E2 * math.sin(phi) ** 2)
    ky = math.radians(1.0) * WGS84_A_M * (1.0 - WGS84_E2) / w**3 / 1e3
    kx = math.radians(1.0) * WGS84_A_M / w * math.cos(phi) / 1e3
    centre = np.array([lat0, lon0, ky, kx, (WGS84_A_M / 1e3) ** 2 / (1.0 + math.tan(phi) ** 2)])
    far = np.empty((6, m))
    for i in range(m):
        far[0, i], far[1, i], far[2, i], far[3, i], far[4, i], far[5, i] = _terms(lat_b[i], lon_b[i])
    hy, hx = step_km / ky, step_km / kx
    r = np.empty((9, m))
    for q, (oy, ox) in enumerate(((0, 0), (1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (1, -1), (-1, 1), (-1, -1))):
        sb, cb, shb, chb, shl, chl = _terms(lat0 + oy * hy, lon0 + ox * hx)
        for i in range(m):
            r[q, i] = _andoyer_m(sb, cb, shb, chb, shl, chl, far[0, i], far[1, i], far[2, i], far[3, i], far[4, i],
                                 far[5, i])  # fmt: skip
    coef = np.empty((m, 6))
    for i in range(m):
        c, n_, s_, e, w_, ne, nw, se, sw = r[:, i]
        coef[i, 0] = c
        coef[i, 1] = (n_ - s_) / (2 * hy)
        coef[i, 2] = (e - w_) / (2 * hx)
        coef[i, 3] = (n_ - 2 * c + s_) / hy**2
        coef[i, 4] = (ne - nw - se + sw) / (4 * hy * hx)
        coef[i, 5] = (e - 2 * c + w_) / hx**2
    return centre, coef, far


@njit(cache=True, nogil=True, inline="always")
def _terms(lat_deg, lon_deg):  # pragma: no cover - compiled
    """`_point_terms` of one point: (sin b, cos b, sin b/2, cos b/2, sin lambda/2, cos lambda/2)."""
    b = math.atan((1.0 - WGS84_F) * math.tan(math.radians(lat_deg)))
    half_lon = math.radians(lon_deg) / 2.0
    return math.sin(b), math.cos(b), math.sin(b / 2.0), math.cos(b / 2.0), math.sin(half_lon), math.cos(half_lon)


@njit(cache=True, nogil=True)
def _expanded_ranges_m(lat, lon, centre, coef, far_terms, tolerance_km, out):  # pragma: no cover - compiled
    """`ranges_about_centre_m`'s loop over the points (`_expanded_point`)."""
    for p in range(lat.shape[0]):
        _expanded_point(p, lat, lon, centre, coef, far_terms, tolerance_km, out)


@njit(cache=True, nogil=True, parallel=True)
def _expanded_ranges_threaded_m(lat, lon, centre, coef, far_terms, tolerance_km, out):  # pragma: no cover
    """`_expanded_ranges_m` on numba's threads (`model.parallel`)."""
    for q in prange(lat.shape[0]):
        _expanded_point(np.intp(q), lat, lon, centre, coef, far_terms, tolerance_km, out)


@njit(cache=True, nogil=True, inline="always")
def _expanded_point(p, lat, lon, centre, coef, far_terms, tolerance_km, out):  # pragma: no cover - compiled
    """Point p's ranges: its offset from the centre (`_expansion`'s) and, per far point, the
    expansion or (beyond its error bound) `_andoyer_m`."""
    lat0, lon0, ky, kx, grid_km2 = centre[0], centre[1], centre[2], centre[3], centre[4]
    dy = lat[p] - lat0
    dx = lon[p] - lon0
    if dx >= 180.0:
        dx -= 360.0
    elif dx < -180.0:
        dx += 360.0
    d_km = math.sqrt((dy * ky) ** 2 + (dx * kx) ** 2)
    cube = d_km * d_km * d_km
    grid = cube / grid_km2  # the (lat, lon) grid's share of the bound
    have_terms = False
    sb = cb = shb = chb = shl = chl = 0.0
    for i in range(coef.shape[0]):
        clear_km = coef[i, 0] / 1e3 - d_km
        if clear_km > 0.0 and 0.25 * cube + (grid - tolerance_km) * clear_km * clear_km <= 0.0:
            out[p, i] = (
                coef[i, 0] + coef[i, 1] * dy + coef[i, 2] * dx
                + 0.5 * coef[i, 3] * dy * dy + coef[i, 4] * dy * dx + 0.5 * coef[i, 5] * dx * dx
            )  # fmt: skip
            continue
        if not have_terms:
            sb, cb, shb, chb, shl, chl = _terms(lat[p], lon[p])
            have_terms = True
        out[p, i] = _andoyer_m(
            sb, cb, shb, chb, shl, chl,
            far_terms[0, i], far_terms[1, i], far_terms[2, i], far_terms[3, i], far_terms[4, i], far_terms[5, i],
        )  # fmt: skip


def radii_of_curvature_m(lat_deg: ArrayLike) -> tuple[NDArray, NDArray]:
    """Meridional (M) and prime-vertical (N) radii of curvature at geodetic latitude."""
    s2 = np.sin(np.radians(np.asarray(lat_deg, dtype=float))) ** 2
    w = np.sqrt(1.0 - WGS84_E2 * s2)
    m = WGS84_A_M * (1.0 - WGS84_E2) / w**3
    n = WGS84_A_M / w
    return m, n


def displace(
    lat_deg: ArrayLike, lon_deg: ArrayLike, east_km: ArrayLike, north_km: ArrayLike
) -> tuple[NDArray, NDArray]:
    """Move points by small east/north displacements (km) in the local tangent plane."""
    lat_deg, lon_deg = np.asarray(lat_deg, dtype=float), np.asarray(lon_deg, dtype=float)
    east_km, north_km = np.asarray(east_km, dtype=float), np.asarray(north_km, dtype=float)
    m, n = radii_of_curvature_m(lat_deg)
    lat = lat_deg + np.degrees(north_km * 1e3 / m)
    lon = lon_deg + np.degrees(east_km * 1e3 / (n * np.cos(np.radians(lat_deg))))
    return lat, wrap_lon(lon)


def local_offsets_km(
    lat_deg: ArrayLike, lon_deg: ArrayLike, lat0: ArrayLike, lon0: ArrayLike
) -> tuple[NDArray, NDArray]:
    """East/north offsets (km) of points from (lat0, lon0) in its tangent plane (the origin
    may be one point, or one per point)."""
    lat0, lon0 = np.asarray(lat0, dtype=float), np.asarray(lon0, dtype=float)
    m, n = radii_of_curvature_m(lat0)
    east = np.radians(wrap_lon(np.asarray(lon_deg) - lon0)) * n * np.cos(np.radians(lat0)) / 1e3
    north = np.radians(np.asarray(lat_deg) - lat0) * m / 1e3
    return east, north


def wrap_lon(lon_deg: ArrayLike) -> NDArray:
    """Longitude wrapped to [-180, 180)."""
    shifted = np.asarray(lon_deg) + 180.0
    if not ((shifted >= 0.0) & (shifted < 360.0)).all():  # else the remainder is `shifted` itself
        shifted = shifted % 360.0  # (numpy's float remainder is slow: skipped when it changes nothing)
    return shifted - 180.0
