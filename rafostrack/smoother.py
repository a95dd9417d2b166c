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

import numpy as np
from numpy.typing import NDArray

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


def _plane_states(cloud: Cloud, index: NDArray[np.intp], ref_lat: float, ref_lon: float) -> NDArray[np.float64]:
    """(n, d) tangent-plane states about (ref_lat, ref_lon): east, north km [, velocity]."""
    east, north = local_offsets_km(cloud.lat[index], cloud.lon[index], ref_lat, ref_lon)
    columns = [east, north]
    if cloud.particles.velocity_km_per_day is not None:
        columns += list(cloud.particles.velocity_km_per_day[index].T)
    return np.column_stack(columns)


def backward_step(
    now: Cloud, nxt: Cloud, smoothed_next: NDArray[np.float64], transition: LinearGaussian
) -> NDArray[np.float64]:
    """Smoothed weights at `now` from the smoothed weights at the next step (module docstring).

    The (J, I) matrix is built in float32 (3x faster; weights agree with float64 to ~1e-6)
    unless the exponents are large enough for float32 rounding to matter, e.g. a
    zero-time step's 1 m kernel. Products and sums avoid BLAS, whose threaded reductions
    would make the result depend on the machine's thread count.
    """
    keep_i = np.flatnonzero(now.weights > _PRUNE * now.weights.max())
    keep_j = np.flatnonzero(smoothed_next > _PRUNE * smoothed_next.max())
    ref = keep_j[np.argmax(smoothed_next[keep_j])]
    ref_lat, ref_lon = float(nxt.lat[ref]), float(nxt.lon[ref])
    white = transition.whitening(_MIN_SD_KM)
    za = np.einsum("kl,lm,im->ik", white, transition.A, _plane_states(now, keep_i, ref_lat, ref_lon))
    zb = np.einsum("kl,jl->jk", white, _plane_states(nxt, keep_j, ref_lat, ref_lon) - transition.b)
    reach = 0.5 * max(float((za * za).sum(axis=1).max()), float((zb * zb).sum(axis=1).max()))
    dtype = np.float32 if reach < _FLOAT32_REACH else np.float64
    log_e = np.einsum("jk,ki->ji", zb.astype(dtype), np.ascontiguousarray(za.T, dtype=dtype))
    log_e += (np.log(now.weights[keep_i]) - 0.5 * (za * za).sum(axis=1)).astype(dtype)[None, :]
    log_e -= log_e.max(axis=1, keepdims=True)
    e = np.exp(log_e, out=log_e)  # (J, I), each row's maximum is 1
    out = np.zeros_like(now.weights)
    ratio = (smoothed_next[keep_j] / e.sum(axis=1, dtype=np.float64)).astype(dtype)
    out[keep_i] = np.einsum("ji,j->i", e, ratio)
    return out / out.sum()


def smooth(clouds: Sequence[Cloud], motion: MotionModel) -> list[NDArray[np.float64]]:
    """Smoothed marginal weights of every step, given the filter's clouds in time order."""
    if not clouds:
        return []
    smoothed = [np.empty(0)] * len(clouds)
    smoothed[-1] = clouds[-1].weights / clouds[-1].weights.sum()
    for t in range(len(clouds) - 2, -1, -1):
        transition = motion.transition(max(days_between(clouds[t].time, clouds[t + 1].time), 0.0))
        smoothed[t] = backward_step(clouds[t], clouds[t + 1], smoothed[t + 1], transition)
    return smoothed
