"""Summaries of a weighted particle cloud: mean, covariance ellipse and separated modes.

Positions are taken in the east/north tangent plane (km) of the heaviest particle, which
is accurate to well under the particle spread at the scales of a float posterior.
Weighted sums use `np.einsum` (numpy's own loops) or compiled loops (the 2-means split),
never BLAS, whose threaded reductions round differently with the thread count: results are
the same bit for bit on any machine.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit
from numpy.typing import NDArray

from ..model.geodesy import displace, local_offsets_km

# Semi-axis scale of the 95% ellipse of a 2-D Gaussian: sqrt(chi2_2(0.95)) = 2.4477, the
# chi-square quantile with 2 degrees of freedom in closed form, -2 log(1 - p).
ELLIPSE_95_SCALE = math.sqrt(-2.0 * math.log1p(-0.95))


@dataclass(frozen=True)
class Gaussian2D:
    """A position with its 2x2 east/north covariance (km^2)."""

    lat: float
    lon: float
    cov_km2: NDArray[np.float64]

    @property
    def sd_km(self) -> float:
        """RMS distance from the mean: sqrt(trace of the covariance)."""
        return float(np.sqrt(max(np.trace(self.cov_km2), 0.0)))

    def ellipse(self) -> tuple[float, float, float]:
        """One-sigma semi-axes (km) and the major axis' direction (deg clockwise from north,
        in [0, 180)); multiply the axes by ELLIPSE_95_SCALE for the 95% ellipse."""
        values, vectors = np.linalg.eigh(self.cov_km2)
        values = np.clip(values, 0.0, None)
        east, north = vectors[:, 1]  # eigenvector of the larger eigenvalue
        angle = float(np.degrees(np.arctan2(east, north)) % 180.0)
        return float(np.sqrt(values[1])), float(np.sqrt(values[0])), angle


@dataclass(frozen=True)
class Modes:
    """Two-cluster split of a posterior; `ambiguous` when the clusters are separate modes."""

    whole: Gaussian2D  # the whole cloud
    first: Gaussian2D  # the heavier cluster
    second: Gaussian2D
    first_weight: float
    second_weight: float
    separation_km: float
    ambiguous: bool
    parted: bool = False  # the two parts lie in regions parted by forbidden ground (`groups`)
    # The modes are the two-filter smoother's two filters held apart (`smoothing.split`): the
    # join weighed them by their evidence, which picks the wrong one too often to report it
    # alone; the whole posterior's mean is reported, its sd covering both.
    split: bool = False

    @property
    def position(self) -> Gaussian2D:
        """The position to report: the heavier mode where there are two separate ones or the
        posterior is parted (its mean may lie on the forbidden ground between), the whole
        where the modes are a split's, else the whole."""
        if self.split:
            return self.whole
        return self.first if self.ambiguous or self.parted else self.whole


def _weighted_mean_cov(xy: NDArray, w: NDArray) -> tuple[NDArray, NDArray]:
    total = w.sum()
    mean = np.einsum("p,pk->k", w, xy) / total
    d = xy - mean
    return mean, np.einsum("p,pi,pj->ij", w, d, d) / total


def _to_gaussian(ref_lat: float, ref_lon: float, mean: NDArray, cov: NDArray) -> Gaussian2D:
    lat, lon = displace(np.array([ref_lat]), np.array([ref_lon]), mean[:1], mean[1:])
    return Gaussian2D(float(lat[0]), float(lon[0]), cov)


def _frame(lat: NDArray, lon: NDArray, weights: NDArray) -> tuple[float, float, NDArray]:
    ref = int(np.argmax(weights))
    east, north = local_offsets_km(lat, lon, lat[ref], lon[ref])
    return float(lat[ref]), float(lon[ref]), np.column_stack([east, north])


def _parted(
    xy: NDArray, weights: NDArray, groups: NDArray, kernel: NDArray, min_weight: float
) -> tuple[tuple[float, NDArray, NDArray], tuple[float, NDArray, NDArray], bool] | None:
    """The two heaviest regions as clusters (mass, mean, covariance), and whether the lighter
    holds `min_weight`; None when one region holds all the mass."""
    names, index = np.unique(groups, return_inverse=True)
    mass = np.bincount(index, weights=weights, minlength=len(names))
    if np.count_nonzero(mass) < 2:
        return None
    heavy = np.argsort(-mass, kind="stable")[:2]
    total = weights.sum()
    clusters = []
    for g in heavy:
        member = index == g
        m, c = _weighted_mean_cov(xy[member], weights[member])
        clusters.append((float(mass[g] / total), m, c + kernel))
    return clusters[0], clusters[1], clusters[1][0] >= min_weight


def summarise(lat: NDArray, lon: NDArray, weights: NDArray) -> Gaussian2D:
    """Weighted mean position and east/north covariance of a particle cloud."""
    ref_lat, ref_lon, xy = _frame(lat, lon, weights)
    mean, cov = _weighted_mean_cov(xy, weights)
    return _to_gaussian(ref_lat, ref_lon, mean, cov)


def two_modes(
    lat: NDArray,
    lon: NDArray,
    weights: NDArray,
    *,
    min_weight: float,
    min_separation_km: float,
    separation_factor: float,
    iterations: int = 20,
    extra_cov_km2: NDArray | None = None,
    groups: NDArray[np.int64] | None = None,
) -> Modes:
    """Split the cloud into two clusters (weighted 2-means, started across the principal
    axis) and decide whether they are separate modes.

    Ambiguous when the lighter cluster holds at least `min_weight` of the mass and the
    distance d between cluster means satisfies d >= `min_separation_km` and
    d >= `separation_factor` * (s_1 + s_2), with s_k the sd of cluster k along the line
    joining the means. A unimodal Gaussian split this way gives d / (s_1 + s_2) ~ 1.3;
    two modes far apart relative to their widths give much larger ratios.

    `extra_cov_km2`: a covariance added to every cluster's (when each particle stands for a
    Gaussian kernel of this covariance, as in a regularised smoother, or for what the
    particles' model leaves out).

    `groups`: region labels of the particles (`likelihoods.MoveFactor.regions`: regions
    parted by forbidden ground). When the cloud holds mass in two or more, the two clusters
    are the two heaviest regions, not a 2-means split; they are separate modes whenever the
    lighter holds `min_weight` (`Modes.parted` either way).
    """
    kernel = np.zeros((2, 2)) if extra_cov_km2 is None else np.asarray(extra_cov_km2)
    carried = weights > 0  # smoothing leaves exact zeros; they belong to no mode
    lat, lon, weights = lat[carried], lon[carried], weights[carried]
    ref_lat, ref_lon, xy = _frame(lat, lon, weights)
    mean, cov = _weighted_mean_cov(xy, weights)
    if groups is not None:
        parted = _parted(xy, weights, np.asarray(groups)[carried], kernel, min_weight)
        if parted is not None:
            (w1, m1, c1), (w2, m2, c2), ambiguous = parted
            whole = _to_gaussian(ref_lat, ref_lon, mean, cov + kernel)
            first, second = _to_gaussian(ref_lat, ref_lon, m1, c1), _to_gaussian(ref_lat, ref_lon, m2, c2)
            return Modes(whole, first, second, w1, w2, float(np.hypot(*(m2 - m1))), ambiguous, True)
    axis = np.linalg.eigh(cov)[1][:, 1]
    side = _two_means(xy, weights, np.einsum("pk,k->p", xy - mean, axis) > 0, iterations)
    whole = _to_gaussian(ref_lat, ref_lon, mean, cov + kernel)
    if side.all() or not side.any():
        return Modes(whole, whole, whole, 1.0, 0.0, 0.0, False)

    (w1, m1, c1), (w2, m2, c2) = _split_clusters(xy, weights, side, kernel)
    d, ambiguous = _separation(m1, c1, m2, c2, w2 >= min_weight, min_separation_km, separation_factor)
    first, second = _to_gaussian(ref_lat, ref_lon, m1, c1), _to_gaussian(ref_lat, ref_lon, m2, c2)
    return Modes(whole, first, second, w1, w2, d, ambiguous)


def _split_clusters(
    xy: NDArray, weights: NDArray, side: NDArray[np.bool_], kernel: NDArray
) -> list[tuple[float, NDArray, NDArray]]:
    """The two sides of the split as clusters (mass fraction, mean, covariance + kernel),
    the heavier first."""
    clusters = []
    for member in (side, ~side):
        w = weights[member]
        m, c = _weighted_mean_cov(xy[member], w)
        clusters.append((float(w.sum() / weights.sum()), m, c + kernel))
    clusters.sort(key=lambda c: -c[0])
    return clusters


def _separation(
    m1: NDArray, c1: NDArray, m2: NDArray, c2: NDArray, heavy_enough: bool, min_km: float, factor: float
) -> tuple[float, bool]:
    """The distance d between the cluster means, and whether they are separate modes:
    the lighter `heavy_enough`, d >= `min_km` and d >= `factor` (s_1 + s_2), s_k the sd of
    cluster k along the line joining the means."""
    gap = m2 - m1
    d = float(np.hypot(*gap))
    u = gap / d if d > 0 else np.array([1.0, 0.0])
    s1, s2 = np.sqrt(max(u @ c1 @ u, 0.0)), np.sqrt(max(u @ c2 @ u, 0.0))
    return d, bool(heavy_enough and d >= min_km and d >= factor * (s1 + s2))


@njit(cache=True, nogil=True)
def _two_means(xy, weights, side, iterations):  # pragma: no cover - compiled
    """Weighted 2-means (Lloyd) from the split `side`: each point to the nearer of the two
    clusters' weighted means, until no point moves, a cluster empties or `iterations`."""
    n = xy.shape[0]
    side = side.copy()
    for _ in range(iterations):
        total = np.zeros((2, 3))  # per cluster: sum w, sum w x, sum w y
        for p in range(n):
            c = 1 if side[p] else 0
            total[c, 0] += weights[p]
            total[c, 1] += weights[p] * xy[p, 0]
            total[c, 2] += weights[p] * xy[p, 1]
        if total[0, 0] == 0.0 or total[1, 0] == 0.0:  # (the zero-weight points were dropped)
            break
        x0, y0 = total[0, 1] / total[0, 0], total[0, 2] / total[0, 0]
        x1, y1 = total[1, 1] / total[1, 0], total[1, 2] / total[1, 0]
        moved = False
        for p in range(n):
            new = (xy[p, 0] - x1) ** 2 + (xy[p, 1] - y1) ** 2 < (xy[p, 0] - x0) ** 2 + (xy[p, 1] - y0) ** 2
            moved = moved or new != side[p]
            side[p] = new
        if not moved:
            break
    return side
