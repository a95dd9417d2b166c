"""Forward-filtering backward-smoothing (FFBSm) of the particle marginals.

Why this smoother: the filter's particles already cover where the float can be; what the
later data change is how much each of them counts. FFBSm reweights the stored filter
particles at every step with the exact recursion for the smoothed marginals (Doucet &
Johansen 2009, eq. 49), so the track, its covariance and the labels use all the data
without a second Monte Carlo layer: no backward-trajectory sampling noise (FFBSi), and no
backward information filter to design for a nonlinear range model (two-filter).
Cost O(N^2) per step for N particles, as N x N transition-density matrices.

With filter weights W_t^i on particles x_t^i (after weighting by y_t, before resampling)
and the motion model's transition density f(x' | x) (`rafostrack.motion`):
    W_{t|T}^i  proportional to  W_t^i sum_j W_{t+1|T}^j f(x_{t+1}^j | x_t^i) / sum_k W_t^k f(x_{t+1}^j | x_t^k),
started from W_{T|T} = W_T. Every motion model is linear-Gaussian in a local tangent plane,
f(x' | x) = N(x'; A x + b, Q): with a whitening W (W Q W^T = I), z_j = W (x'_j - b) and
c_i = W A x_i, log f_ji = z_j . c_i - |c_i|^2 / 2 - |z_j|^2 / 2 + const. The last two
terms are constant along row j and cancel, so with E_ji = W_t^i f_ji / max_i(W_t^i f_ji)
and S_j = sum_i E_ji this is W_{t|T} proportional to E^T (W_{t+1|T} / S).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.special import logsumexp

from .domain import Cloud, days_between
from .geodesy import local_offsets_km
from .motion import LinearGaussian, MotionModel

# Particles whose weight is below this fraction of the largest weight are left out of the
# O(N^2) products; their contribution is below float64 resolution of the result.
_PRUNE = 1e-14
# Transition sd floor (km) for steps at the same instant (e.g. a fix at a window's time),
# where the particles are copies: a 1 m kernel links each copy to its own ancestor.
_MIN_SD_KM = 1e-3
# Largest |z|^2 / 2 for which the kernel exponents are built in float32.
_FLOAT32_REACH = 1e3
# A broad mixture kernel is left out of a row where it adds less than this fraction.
_MIXTURE_TOL = 1e-4
_LOG_2PI = float(np.log(2.0 * np.pi))


def _plane_states(cloud: Cloud, index: NDArray[np.intp], ref_lat: float, ref_lon: float) -> NDArray[np.float64]:
    """(n, d) tangent-plane states about (ref_lat, ref_lon): east, north km [, velocity]."""
    east, north = local_offsets_km(cloud.lat[index], cloud.lon[index], ref_lat, ref_lon)
    columns = [east, north]
    if cloud.particles.velocity_km_per_day is not None:
        columns += list(cloud.particles.velocity_km_per_day[index].T)
    return np.column_stack(columns)


def _log_kernel(za: NDArray, zb: NDArray, dtype: type) -> NDArray:
    """(J, I) of zb_j . za_i - |za_i|^2 / 2 in `dtype`, without BLAS."""
    out = np.einsum("jk,ki->ji", zb.astype(dtype), np.ascontiguousarray(za.T, dtype=dtype))
    out -= (0.5 * (za * za).sum(axis=1)).astype(dtype)[None, :]
    return out


def _whitened(kernel: LinearGaussian, xa: NDArray, xb: NDArray) -> tuple[NDArray, NDArray, NDArray, float]:
    """z_a = W A x_a, z_b = W (x_b - b), W and log|det W| of a kernel (floored, `_MIN_SD_KM`)."""
    white = kernel.whitening(_MIN_SD_KM)
    za = np.einsum("kl,lm,im->ik", white, kernel.A, xa)
    zb = np.einsum("kl,jl->jk", white, xb - kernel.b)
    return za, zb, white, float(np.linalg.slogdet(white)[1])


def backward_step(
    now: Cloud,
    nxt: Cloud,
    smoothed_next: NDArray[np.float64],
    components: list[tuple[float, LinearGaussian]],
) -> NDArray[np.float64]:
    """Smoothed weights at `now` from the smoothed weights at the next step (module docstring),
    for a transition that is a mixture of linear-Gaussian kernels, the first the drift model
    and any others broad (e.g. `motion.JumpMixture`'s jump).

    The first kernel's (J, I) matrix is built in float32 (3x faster; weights agree with
    float64 to ~1e-6) unless the exponents are large enough for float32 rounding to
    matter, e.g. a zero-time step's 1 m kernel. A further kernel k enters row j only where
    its peak density could add at least `_MIXTURE_TOL` to that row's predictive density
    sum_i W_i f(x_j | x_i); elsewhere its share is below the float32 resolution of the
    weights. Rows then combine in log space. Products and sums avoid BLAS, whose threaded
    reductions would make the result depend on the machine's thread count.
    """
    keep_i = np.flatnonzero(now.weights > _PRUNE * now.weights.max())
    keep_j = np.flatnonzero(smoothed_next > _PRUNE * smoothed_next.max())
    ref = keep_j[np.argmax(smoothed_next[keep_j])]
    ref_lat, ref_lon = float(nxt.lat[ref]), float(nxt.lon[ref])
    xa = _plane_states(now, keep_i, ref_lat, ref_lon)
    xb = _plane_states(nxt, keep_j, ref_lat, ref_lon)
    log_w = np.log(now.weights[keep_i])
    (w0, k0), *others = [(w, k) for w, k in components if w > 0]
    za, zb, _, log_det = _whitened(k0, xa, xb)
    reach = 0.5 * max(float((za * za).sum(axis=1).max()), float((zb * zb).sum(axis=1).max()))
    dtype = np.float32 if reach < _FLOAT32_REACH else np.float64
    log_e = _log_kernel(za, zb, dtype)
    log_e += log_w.astype(dtype)[None, :]
    row_max = log_e.max(axis=1, keepdims=True)
    log_e -= row_max
    e = np.exp(log_e, out=log_e)  # (J, I), each row's maximum is 1
    # log sum_i W_i f0(x_j | x_i), with f0's row terms (its |z_j|^2 and normaliser).
    row0 = np.log(w0) + log_det - 0.5 * k0.dim * _LOG_2PI - 0.5 * (zb * zb).sum(axis=1)
    log_pred = row_max[:, 0].astype(np.float64) + np.log(e.sum(axis=1, dtype=np.float64)) + row0
    extra = []  # (rows, (rows, I) kernel values in the common row scale) per broad kernel
    for weight, kernel in others:
        zak, zbk, _, log_det_k = _whitened(kernel, xa, xb)
        log_peak = np.log(weight) + log_det_k - 0.5 * kernel.dim * _LOG_2PI
        rows = np.flatnonzero(log_peak - log_pred > np.log(_MIXTURE_TOL))
        if len(rows) == 0:
            continue
        rowk = log_peak - 0.5 * (zbk[rows] * zbk[rows]).sum(axis=1)
        log_k = _log_kernel(zak, zbk[rows], np.float64) + log_w[None, :] + rowk[:, None]
        extra.append((rows, log_k))
    for rows, log_k in extra:
        log_pred[rows] = np.logaddexp(log_pred[rows], logsumexp(log_k, axis=1))
    # sum_j W_{t+1|T}^j W_i f_ji / pred_j, with W_i f0_ji = e_ji exp(row_max_j + row0_j).
    scale = smoothed_next[keep_j] * np.exp(row_max[:, 0].astype(np.float64) + row0 - log_pred)
    contrib = np.einsum("ji,j->i", e, scale.astype(e.dtype)).astype(np.float64)
    for rows, log_k in extra:
        contrib += np.einsum("ji,j->i", np.exp(log_k - log_pred[rows, None]), smoothed_next[keep_j][rows])
    out = np.zeros_like(now.weights)
    out[keep_i] = contrib
    return out / out.sum()


def silverman_bandwidth(n: int, dim: int) -> float:
    """h of the regularised particle filter's Gaussian kernel: (4 / (n (d + 2)))^(1 / (d + 4))
    (Silverman's rule; Musso, Oudjane & Le Gland 2001)."""
    return float((4.0 / (n * (dim + 2.0))) ** (1.0 / (dim + 4.0)))


def cloud_covariance(cloud: Cloud) -> NDArray[np.float64]:
    """Weighted covariance (d, d) of a cloud's tangent-plane states (km; km/day)."""
    ref = int(np.argmax(cloud.weights))
    states = _plane_states(cloud, np.arange(len(cloud.weights)), float(cloud.lat[ref]), float(cloud.lon[ref]))
    w = cloud.weights / cloud.weights.sum()
    d = states - np.einsum("p,pk->k", w, states)
    return np.einsum("p,pi,pj->ij", w, d, d)


def regularised(kernel: LinearGaussian, spread: NDArray[np.float64]) -> LinearGaussian:
    """The transition from a particle smeared by a Gaussian kernel of covariance `spread`:
    integral of N(x'; A s + b, Q) N(s; s_i, spread) ds = N(x'; A s_i + b, Q + A spread A^T)."""
    q = kernel.Q + kernel.A @ spread @ kernel.A.T
    values, vectors = np.linalg.eigh(0.5 * (q + q.T))
    return LinearGaussian(kernel.A, kernel.b, vectors * np.sqrt(np.clip(values, 0.0, None)))


@dataclass(frozen=True)
class Smoothed:
    """Smoothed weights of every step, and the covariance (km^2, east/north) of the kernel
    each particle stands for (zero when not regularised)."""

    weights: list[NDArray[np.float64]]
    kernel_cov_km2: list[NDArray[np.float64]]


def smooth(clouds: Sequence[Cloud], motion: MotionModel, *, regularise: bool = True) -> Smoothed:
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
    """
    if not clouds:
        return Smoothed([], [])
    smoothed = [np.empty(0)] * len(clouds)
    smoothed[-1] = clouds[-1].weights / clouds[-1].weights.sum()
    h2 = silverman_bandwidth(len(clouds[0].weights), motion.dim) ** 2 if regularise else 0.0
    spreads = [h2 * cloud_covariance(c) if h2 > 0 else np.zeros((motion.dim, motion.dim)) for c in clouds]
    for t in range(len(clouds) - 2, -1, -1):
        components = motion.components(max(days_between(clouds[t].time, clouds[t + 1].time), 0.0))
        if h2 > 0:
            components = [(components[0][0], regularised(components[0][1], spreads[t])), *components[1:]]
        smoothed[t] = backward_step(clouds[t], clouds[t + 1], smoothed[t + 1], components)
    return Smoothed(smoothed, [s[:2, :2] for s in spreads])
