"""A float's observations as a likelihood of leg positions: arrival windows and GPS fixes.

Each listening window's evidence is the tracker's own: log p(window | position) from the
configured arrival likelihood (ranked signals, association summed out by the exact
engine). A sampler asks for it at a new position for many windows per move, so each
window's log-likelihood is computed once on a square grid of plane points (spacing h,
half-width W) about the smoother's position there, in one vectorised call per window,
and read by bilinear interpolation. Outside its grid a window's log-likelihood is the
value at the nearest edge point minus d^2 / (2 s^2), d the distance outside and s the
window's own width (TOA sd x sound speed): legs may not wander far from where the
arrivals put the float. Launch and end fixes are Gaussian, sd per axis as configured.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..domain import Particles, Window
from ..likelihoods import ArrivalLikelihood
from .plane import Plane

WINDOW, FIX = 0, 1


@dataclass(frozen=True)
class Grids:
    """Each window's log-likelihood on an (n, n) grid: node (i, k) is at centre + h (i - m, k - m)."""

    centres: NDArray[np.float64]  # (W, 2) plane km
    spacing_km: float
    values: NDArray[np.float64]  # (W, n, n), first index east

    @property
    def half(self) -> int:
        return (self.values.shape[1] - 1) // 2


def build_grids(
    likelihood: ArrivalLikelihood, windows: list[Window], centres: NDArray, plane: Plane,
    spacing_km: float, half_width_km: float,
) -> Grids:  # fmt: skip
    """Evaluate every window's log-likelihood on its grid (one call per window)."""
    half = max(1, round(half_width_km / spacing_km))
    offsets = spacing_km * np.arange(-half, half + 1)
    de, dn = np.meshgrid(offsets, offsets, indexing="ij")
    values = np.empty((len(windows), 2 * half + 1, 2 * half + 1))
    for j, window in enumerate(windows):
        lat, lon = plane.from_plane(np.stack([centres[j, 0] + de.ravel(), centres[j, 1] + dn.ravel()], axis=-1))
        loglik = likelihood.evaluate(Particles(lat, lon), window, marginals=False).loglik
        values[j] = np.maximum(np.nan_to_num(loglik, nan=-1e6, neginf=-1e6), -1e6).reshape(de.shape)
    return Grids(np.asarray(centres, dtype=float), spacing_km, values)


def grid_loglik(grids: Grids, which: NDArray[np.intp], xy: NDArray, outside_sd_km: float) -> NDArray[np.float64]:
    """Bilinear log-likelihood of windows `which` at plane points `xy` (module docstring)."""
    n = grids.values.shape[1]
    u = (xy[:, 0] - grids.centres[which, 0]) / grids.spacing_km + grids.half
    v = (xy[:, 1] - grids.centres[which, 1]) / grids.spacing_km + grids.half
    uc, vc = np.clip(u, 0.0, n - 1.0), np.clip(v, 0.0, n - 1.0)
    i0 = np.minimum(uc.astype(np.intp), n - 2)
    k0 = np.minimum(vc.astype(np.intp), n - 2)
    fu, fv = uc - i0, vc - k0
    g = grids.values
    value = (
        (1 - fu) * (1 - fv) * g[which, i0, k0]
        + fu * (1 - fv) * g[which, i0 + 1, k0]
        + (1 - fu) * fv * g[which, i0, k0 + 1]
        + fu * fv * g[which, i0 + 1, k0 + 1]
    )
    outside_km = np.hypot(u - uc, v - vc) * grids.spacing_km
    return value - 0.5 * (outside_km / outside_sd_km) ** 2


@dataclass(frozen=True)
class FloatEvidence:
    """Per-observation log-likelihood terms at ascending times (days since launch): windows
    (grid look-ups) and fixes (Gaussian), for the sampler. Its levels are wiggle sds s (the
    float's departures from its legs, `smooth_grids`), which the sampler moves among
    (uniform prior); level 0 is s = 0 when no wiggle is given."""

    times: NDArray[np.float64]  # (n_obs,)
    kind: NDArray[np.intp]  # WINDOW or FIX
    window: NDArray[np.intp]  # grid row of each window observation (-1 for fixes)
    fix_xy: NDArray[np.float64]  # (n_obs, 2), NaN for windows
    fix_sd_km: NDArray[np.float64]  # (n_obs,), NaN for windows
    grids: Grids  # the windows' own log-likelihoods
    outside_sd_km: float
    wiggle_sd_km: tuple[float, ...] = (0.0,)
    smoothed: tuple[Grids, ...] = ()  # grids convolved with each wiggle sd (default: `grids`)
    start_level: int = 0

    @property
    def n_levels(self) -> int:
        return len(self.wiggle_sd_km)

    def terms(self, xy: NDArray, index: slice, level: int = 0) -> NDArray[np.float64]:
        kind = self.kind[index]
        out = np.empty(len(xy))
        w = kind == WINDOW
        if w.any():
            grids = self.smoothed[level] if self.smoothed else self.grids
            out[w] = grid_loglik(grids, self.window[index][w], xy[w], self.outside_sd_km)
        if (~w).any():
            r = xy[~w] - self.fix_xy[index][~w]
            sd = self.fix_sd_km[index][~w]
            out[~w] = -0.5 * (r[:, 0] ** 2 + r[:, 1] ** 2) / sd**2 - np.log(2 * np.pi * sd**2)
        return out


def float_evidence(
    window_days: NDArray, grids: Grids, fixes: list[tuple[float, NDArray, float]], outside_sd_km: float,
    wiggle_sd_km: tuple[float, ...] = (0.0,),
) -> FloatEvidence:  # fmt: skip
    """Windows at `window_days` (one grid row each) and fixes (day, plane xy, sd km), in time
    order; the grids smoothed for each wiggle sd, the sampler starting at the middle one."""
    times = np.concatenate([np.asarray(window_days, dtype=float), [f[0] for f in fixes]])
    kind = np.concatenate([np.full(len(window_days), WINDOW), np.full(len(fixes), FIX)])
    window = np.concatenate([np.arange(len(window_days)), np.full(len(fixes), -1)])
    fix_xy = np.vstack([np.full((len(window_days), 2), np.nan), *[np.asarray(f[1])[None, :] for f in fixes]])
    fix_sd = np.concatenate([np.full(len(window_days), np.nan), [f[2] for f in fixes]])
    order = np.argsort(times, kind="stable")
    smoothed = tuple(smooth_grids(grids, s) for s in wiggle_sd_km)
    return FloatEvidence(times[order], kind[order].astype(np.intp), window[order].astype(np.intp), fix_xy[order],
                         fix_sd[order], grids, outside_sd_km, tuple(wiggle_sd_km), smoothed,
                         len(wiggle_sd_km) // 2)  # fmt: skip


def smooth_grids(grids: Grids, wiggle_sd_km: float) -> Grids:
    """Each window's likelihood with the float allowed to sit off its leg: the position is
    x = z + e, e ~ N(0, s^2 I) independently per window, so the evidence of the leg position
    z is m(z) = int p(window | x) N(x; z, s^2 I) dx, a Gaussian convolution of the grid
    (in linear space; zero beyond the grid). s = 0 leaves the grids as they are."""
    if wiggle_sd_km <= 0:
        return grids
    from scipy.ndimage import gaussian_filter

    top = grids.values.max(axis=(1, 2), keepdims=True)
    width = wiggle_sd_km / grids.spacing_km
    smooth = gaussian_filter(np.exp(grids.values - top), sigma=(0.0, width, width), mode="constant", truncate=4.0)
    return Grids(grids.centres, grids.spacing_km, np.log(np.maximum(smooth, 1e-300)) + top)


def window_positions(
    grids: Grids, which: NDArray[np.intp], leg_xy: NDArray, wiggle_sd_km: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Posterior mean (S, n, 2) and covariance (S, n, 2, 2) of the float's position x at
    windows `which`, given leg positions z (S, n, 2): p(x | z, window) ~ p(window | x)
    N(x; z, s^2 I) on the grid nodes (separable in east and north). With s = 0, x = z."""
    s_count, n = leg_xy.shape[:2]
    if wiggle_sd_km <= 0:
        return leg_xy.copy(), np.zeros((s_count, n, 2, 2))
    h, m = grids.spacing_km, grids.half
    nodes = h * np.arange(-m, m + 1)
    like = np.exp(grids.values[which] - grids.values[which].max(axis=(1, 2), keepdims=True))  # (n, g, g)
    offset = leg_xy - grids.centres[which][None, :, :]  # (S, n, 2), relative to the grid centres
    ge = np.exp(-0.5 * ((nodes[None, None, :] - offset[..., 0:1]) / wiggle_sd_km) ** 2)  # (S, n, g)
    gn = np.exp(-0.5 * ((nodes[None, None, :] - offset[..., 1:2]) / wiggle_sd_km) ** 2)
    a_gn = np.einsum("wik,swk->swi", like, gn)  # sum over north nodes
    a_gn_y = np.einsum("wik,swk->swi", like, gn * nodes)
    a_gn_yy = np.einsum("wik,swk->swi", like, gn * nodes**2)
    z = np.einsum("swi,swi->sw", ge, a_gn)
    z = np.where(z > 0, z, np.nan)
    ex = np.einsum("swi,swi->sw", ge * nodes, a_gn) / z
    ey = np.einsum("swi,swi->sw", ge, a_gn_y) / z
    exx = np.einsum("swi,swi->sw", ge * nodes**2, a_gn) / z
    eyy = np.einsum("swi,swi->sw", ge, a_gn_yy) / z
    exy = np.einsum("swi,swi->sw", ge * nodes, a_gn_y) / z
    mean = np.stack([ex, ey], axis=-1)
    cov = np.stack([np.stack([exx - ex**2, exy - ex * ey], -1), np.stack([exy - ex * ey, eyy - ey**2], -1)], -2)
    far = np.isnan(z)  # the leg is off the grid: fall back on the leg position
    mean = np.where(far[..., None], offset, mean) + grids.centres[which][None, :, :]
    cov = np.where(far[..., None, None], 0.0, cov)
    return mean, cov
