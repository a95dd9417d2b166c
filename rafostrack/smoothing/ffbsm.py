"""Forward-filtering backward-smoothing (FFBSm) of the particle marginals.

Why this smoother: the filter's particles already cover where the float can be; what the
later data change is how much each of them counts. FFBSm reweights the stored filter
particles at every step with the recursion for the smoothed marginals (Doucet & Johansen
2009, eq. 49), so the track, its covariance and the labels use all the data; no backward
information filter to design for a nonlinear range model (two-filter).

With filter weights W_t^i on particles x_t^i (after weighting by y_t, before resampling)
and the motion model's transition density f(x' | x) (`rafostrack.motion`):
    W_{t|T}^i  proportional to  W_t^i sum_j W_{t+1|T}^j f(x_{t+1}^j | x_t^i) / sum_k W_t^k f(x_{t+1}^j | x_t^k),
started from W_{T|T} = W_T. Every motion model is linear-Gaussian in a local tangent plane,
f(x' | x) = N(x'; A x + b, Q) (or a mixture of such), evaluated after whitening
(`ffbsm_kernel`). Exact FFBSm costs O(N^2) per step; when more than `MAX_ROWS` particles
carry the smoothed weights at t + 1, they are represented by `MAX_ROWS` equal-weight
quantile points of those weights (the sum over j is then a stratified estimate); a filter
cloud of more than `MAX_COLUMNS` particles is smoothed on that many quantile points of its
filter weights. O(min(N, MAX_COLUMNS) MAX_ROWS) per step, whatever N. (Backward simulation,
FFBSi, is O(N M) for M trajectories too, but leaves only M points per step.)
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..domain import Cloud, days_between
from ..filtering.resampling import quantile_points
from ..model.geodesy import local_offsets_km
from ..motion import LinearGaussian, MotionModel
from .ffbsm_kernel import backward_weights

# Particles whose weight is below this fraction of the largest weight are left out of the
# O(N^2) products; their contribution is below float64 resolution of the result.
PRUNE = 1e-14
# Transition sd floor (km) for steps at the same instant (e.g. a fix at a window's time),
# where the particles are copies: a 1 m kernel links each copy to its own ancestor.
_MIN_SD_KM = 1e-3
_LOG_2PI = float(np.log(2.0 * np.pi))
# Rows of the backward step: the smoothed weights at t + 1, when more particles carry them,
# are represented by this many equal-weight points (deterministic stratified quantiles).
MAX_ROWS = 512
# Columns: a filter cloud of more particles is smoothed on this many of them, its quantile
# points (`resampling.quantile_points`); the others get smoothed weight zero.
MAX_COLUMNS = 2000


def plane_states(cloud: Cloud, index: NDArray[np.intp], ref_lat: float, ref_lon: float) -> NDArray[np.float64]:
    """(n, d) tangent-plane states about (ref_lat, ref_lon): east, north km [, velocity]
    [, float clock s] (the layout of `MotionModel.components`)."""
    east, north = local_offsets_km(cloud.lat[index], cloud.lon[index], ref_lat, ref_lon)
    columns = [east, north]
    if cloud.particles.velocity_km_per_day is not None:
        columns += list(cloud.particles.velocity_km_per_day[index].T)
    if cloud.particles.clock_s is not None:
        columns.append(cloud.particles.clock_s[index])
    return np.column_stack(columns)


def whitened(
    components: list[tuple[float, LinearGaussian]], origins: NDArray[np.float64], destinations: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The compiled kernels' inputs for a mixture of transitions sum_c w_c N(x'; A_c x + b_c,
    Q_c): za (C, I, d) = W_c A_c x_i for the origins, zb (C, J, d) = W_c (x'_j - b_c) for the
    destinations, n_c = log w_c + log|W_c| - d/2 log 2 pi, with W_c the whitening of Q_c, so
    that log f_c(x'_j | x_i) = n_c - |zb_cj - za_ci|^2 / 2."""
    za, zb, log_norm = [], [], []
    for weight, kernel in components:
        if weight <= 0:
            continue
        white, log_det = kernel.whitened(_MIN_SD_KM)
        za.append(np.einsum("km,im->ik", np.einsum("kl,lm->km", white, kernel.A), origins))
        zb.append(np.einsum("kl,jl->jk", white, destinations - kernel.b))
        log_norm.append(np.log(weight) + log_det - 0.5 * kernel.dim * _LOG_2PI)
    return np.ascontiguousarray(za), np.ascontiguousarray(zb), np.array(log_norm)


def backward_step(
    now: Cloud,
    nxt: Cloud,
    smoothed_next: NDArray[np.float64],
    components: list[tuple[float, LinearGaussian]],
    max_rows: int = MAX_ROWS,
) -> NDArray[np.float64]:
    """Smoothed weights at `now` from the smoothed weights at the next step (module docstring),
    for a transition that is a mixture of linear-Gaussian kernels (`ffbsm_kernel`). With
    more than `max_rows` particles carrying the next step's smoothed weights they are
    represented by `max_rows` equal-weight quantile points (`resampling.quantile_points`):
    O(N max_rows) per step instead of O(N^2), the smoothed weight of every particle of `now`
    still computed."""
    keep_i = np.flatnonzero(now.weights > PRUNE * now.weights.max())
    rows, v = quantile_points(smoothed_next, max_rows, PRUNE)
    ref = rows[np.argmax(v)]
    ref_lat, ref_lon = float(nxt.lat[ref]), float(nxt.lon[ref])
    za, zb, log_norm = whitened(
        components, plane_states(now, keep_i, ref_lat, ref_lon), plane_states(nxt, rows, ref_lat, ref_lon)
    )
    result = np.zeros_like(now.weights)
    result[keep_i] = backward_weights(za, zb, log_norm, np.log(now.weights[keep_i]), v)
    return result / result.sum()


def silverman_bandwidth(n: int, dim: int) -> float:
    """h of the regularised particle filter's Gaussian kernel: (4 / (n (d + 2)))^(1 / (d + 4))
    (Silverman's rule; Musso, Oudjane & Le Gland 2001)."""
    return float((4.0 / (n * (dim + 2.0))) ** (1.0 / (dim + 4.0)))


def cloud_covariance(cloud: Cloud) -> NDArray[np.float64]:
    """Weighted covariance (d, d) of a cloud's tangent-plane states (km; km/day)."""
    ref = int(np.argmax(cloud.weights))
    states = plane_states(cloud, np.arange(len(cloud.weights)), float(cloud.lat[ref]), float(cloud.lon[ref]))
    w = cloud.weights / cloud.weights.sum()
    d = states - np.einsum("p,pk->k", w, states)
    return np.einsum("p,pi,pj->ij", w, d, d)


def regularised(kernel: LinearGaussian, spread: NDArray[np.float64], *, at_destination: bool = False) -> LinearGaussian:
    """The transition from a particle smeared by a Gaussian kernel of covariance `spread`:
    integral of N(x'; A s + b, Q) N(s; s_i, spread) ds = N(x'; A s_i + b, Q + A spread A^T);
    `at_destination`: to a smeared particle, N(x'_j; A x + b, Q + spread)."""
    q = kernel.Q + (spread if at_destination else kernel.A @ spread @ kernel.A.T)
    values, vectors = np.linalg.eigh(0.5 * (q + q.T))
    return LinearGaussian(kernel.A, kernel.b, vectors * np.sqrt(np.clip(values, 0.0, None)))


@dataclass(frozen=True)
class Smoothed:
    """Smoothed weights of every step, and the covariance (km^2, east/north) of the kernel
    each particle stands for (zero when not regularised)."""

    weights: list[NDArray[np.float64]]
    kernel_cov_km2: list[NDArray[np.float64]]

    def part(self, steps: range) -> Smoothed:
        """Those of `steps` (a range of step indices) only."""
        return Smoothed(self.weights[steps.start : steps.stop], self.kernel_cov_km2[steps.start : steps.stop])


def column_points(cloud: Cloud, max_columns: int) -> tuple[Cloud, NDArray[np.intp]]:
    """The cloud on at most `max_columns` of its particles (quantile points of its weights),
    and their indices."""
    if len(cloud.weights) <= max_columns:
        return cloud, np.arange(len(cloud.weights))
    index, weights = quantile_points(cloud.weights, max_columns)
    return Cloud(cloud.time, cloud.particles.take(index), weights), index


def smooth(
    clouds: Sequence[Cloud], motion: MotionModel, *, regularise: bool = True, max_columns: int = MAX_COLUMNS
) -> Smoothed:
    """Smoothed marginal weights of every step, given the filter's clouds in time order.

    `regularise`: each filter particle stands for a Gaussian kernel of covariance h^2 Sigma_t
    (Sigma_t the cloud's covariance, h Silverman's bandwidth), as in a regularised particle
    filter, so that the drift model's transition from it is `regularised`. With a peaked
    transition (a velocity-persistent model moves a float ~1 km a day about its
    prediction) the exact FFBSm weights of N particles in four dimensions collapse onto a
    few of them, and the smoothed spread with them; the kernel keeps each step's smoothed
    weights spread over the particles that the data allow, at the price of a posterior
    slightly wider than exact (by about h^2 Sigma_t: a few per cent of the filter's spread).
    The smoothed marginal is then the mixture of those kernels: its covariance is the
    weighted particles' plus h^2 Sigma_t (`Smoothed.kernel_cov_km2`, the position block).

    A cloud of more than `max_columns` particles is smoothed on `max_columns` quantile points
    of its filter weights (`column_points`): a filter of many particles holds more of the
    posterior's modes through the forward pass, and its backward pass costs no more than
    `max_columns` x `MAX_ROWS` per step.
    """
    if not clouds:
        return Smoothed([], [])
    columns = [column_points(c, max_columns) for c in clouds]
    points = [cloud for cloud, _ in columns]
    smoothed_points = [np.empty(0)] * len(points)
    smoothed_points[-1] = points[-1].weights / points[-1].weights.sum()
    h2 = silverman_bandwidth(len(points[0].weights), motion.dim) ** 2 if regularise else 0.0
    spreads = [h2 * cloud_covariance(c) if h2 > 0 else np.zeros((motion.dim, motion.dim)) for c in points]
    for t in range(len(points) - 2, -1, -1):
        components = motion.components(max(days_between(points[t].time, points[t + 1].time), 0.0))
        if h2 > 0:
            components = [(components[0][0], regularised(components[0][1], spreads[t])), *components[1:]]
        smoothed_points[t] = backward_step(points[t], points[t + 1], smoothed_points[t + 1], components)
    smoothed = []
    for cloud, (_, index), weights in zip(clouds, columns, smoothed_points, strict=True):
        full = np.zeros(len(cloud.weights))
        full[index] = weights
        smoothed.append(full)
    return Smoothed(smoothed, [s[:2, :2] for s in spreads])
