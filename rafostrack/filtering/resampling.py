"""Particle weights in log space, effective sample size, and resampling schemes.

Every scheme maps normalised weights W (N,) to M ancestor indices (M = N unless given)
with E[copies of p] = M W_p; they differ in variance (systematic and stratified are lower
than multinomial; residual copies floor(M W_p) deterministically). `RESAMPLERS` maps the
config's `[filter] resampling` to a scheme. `resample_within` resamples each mode of a
multimodal cloud on its own, keeping the modes' masses (`rafostrack.filtering.modes`). Sums avoid
BLAS, whose threaded reductions would make results depend on the machine's thread count.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numba import njit
from numpy.typing import NDArray

Resampler = Callable[..., NDArray[np.intp]]  # (weights, rng, n=None) -> n ancestor indices


def log_sum_exp(log_w: NDArray, scale: NDArray | None = None) -> float:
    """log sum_p b_p exp(log_w_p) (b = `scale`, non-negative; 1 when None), summed about the
    largest term so that nothing overflows; -inf when every term is zero. (What
    `scipy.special.logsumexp` gives, for one 1-d array, without its per-call overhead: the
    filter calls this a few times per window.)"""
    if scale is not None:
        with np.errstate(divide="ignore"):
            log_w = log_w + np.log(scale)
    top = float(np.max(log_w))
    if not np.isfinite(top):
        return top
    return top + float(np.log(np.sum(np.exp(log_w - top))))


def normalise_log_weights(log_w: NDArray) -> tuple[NDArray[np.float64], float]:
    """Normalised weights W_p = exp(log_w_p - log sum_q exp(log_w_q)) and the log-sum."""
    log_sum = log_sum_exp(log_w)
    return np.exp(log_w - log_sum), log_sum


def ess(weights: NDArray) -> float:
    """Effective sample size 1 / sum W_p^2 of normalised weights."""
    return float(1.0 / np.einsum("p,p->", weights, weights))


def _inverse_cdf(weights: NDArray, points: NDArray) -> NDArray[np.intp]:
    """Indices p with C_{p-1} <= u < C_p for sorted points u in [0, 1)."""
    cumulative = np.cumsum(weights)
    cumulative[-1] = 1.0  # guard against round-off leaving the last point unmatched
    out = np.empty(len(points), dtype=np.intp)
    _merge_search(cumulative, np.ascontiguousarray(points, dtype=np.float64), out)
    return out


@njit(cache=True, nogil=True)
def _merge_search(cumulative, points, out):  # pragma: no cover - compiled
    """out[k] = the first p with cumulative[p] > points[k] (numpy's searchsorted, side
    "right", capped at the last index), the points sorted: one pass over both, O(N + M),
    where a binary search per point costs O(M log N) (eight times as long at 10,000)."""
    p = 0
    last = cumulative.shape[0] - 1
    for k in range(points.shape[0]):
        while p < last and cumulative[p] <= points[k]:
            p += 1
        out[k] = p


def quantile_points(weights: NDArray, n: int, prune: float = 0.0) -> tuple[NDArray[np.intp], NDArray[np.float64]]:
    """At most `n` particles standing for `weights` (N,), and their normalised weights: the
    particles above `prune` x the largest weight as they are when no more than `n`; else
    those at the quantiles (k + 1/2) / n of the cumulative sum, each weighted by the number
    of quantiles it holds / n (deterministic stratification: no random draw)."""
    keep = np.flatnonzero(weights > prune * weights.max())
    if len(keep) <= n:
        return keep, weights[keep] / weights[keep].sum()
    cumulative = np.cumsum(weights[keep])
    points = (np.arange(n) + 0.5) / n * cumulative[-1]
    picked, counts = np.unique(np.searchsorted(cumulative, points, side="right"), return_counts=True)
    return keep[np.minimum(picked, len(keep) - 1)], counts / n


def systematic(weights: NDArray, rng: np.random.Generator, n: int | None = None) -> NDArray[np.intp]:
    """Systematic resampling: one uniform U, points (U + k) / M, k = 0..M-1.

    Particle p is copied floor(M W_p) or ceil(M W_p) times.
    """
    n = len(weights) if n is None else n
    return _inverse_cdf(weights, (rng.random() + np.arange(n)) / n)


def stratified(weights: NDArray, rng: np.random.Generator, n: int | None = None) -> NDArray[np.intp]:
    """Stratified resampling: one uniform per stratum, points (U_k + k) / M."""
    n = len(weights) if n is None else n
    return _inverse_cdf(weights, (rng.random(n) + np.arange(n)) / n)


def multinomial(weights: NDArray, rng: np.random.Generator, n: int | None = None) -> NDArray[np.intp]:
    """Multinomial resampling: M independent draws from W (sorted uniforms)."""
    n = len(weights) if n is None else n
    return _inverse_cdf(weights, np.sort(rng.random(n)))


def residual(weights: NDArray, rng: np.random.Generator, n: int | None = None) -> NDArray[np.intp]:
    """Residual resampling: floor(M W_p) copies of p, the R remaining by multinomial
    draws from the residual weights M W_p - floor(M W_p)."""
    n = len(weights) if n is None else n
    scaled = n * np.asarray(weights, dtype=float)
    copies = np.floor(scaled).astype(np.intp)
    fixed = np.repeat(np.arange(len(weights)), copies)
    remaining = n - len(fixed)
    if remaining == 0:
        return fixed
    rest = scaled - copies
    extra = _inverse_cdf(rest / rest.sum(), np.sort(rng.random(remaining)))
    return np.sort(np.concatenate([fixed, extra]))


RESAMPLERS: dict[str, Resampler] = {
    "systematic": systematic,
    "stratified": stratified,
    "residual": residual,
    "multinomial": multinomial,
}


def within_mode_ess(weights: NDArray, labels: NDArray[np.intp]) -> float:
    """Sum over modes of each mode's own effective sample size, (sum W)^2 / sum W^2 over
    its particles: how many particles really serve the modes, whatever their masses."""
    n_modes = int(labels.max()) + 1
    mass = np.bincount(labels, weights=weights, minlength=n_modes)
    square = np.bincount(labels, weights=weights * weights, minlength=n_modes)
    carried = square > 0
    return float(np.sum(mass[carried] ** 2 / square[carried]))


def allocate(mass: NDArray, n: int, min_count: int) -> NDArray[np.intp]:
    """Particles per mode: `min_count` each, the rest in proportion to the masses (largest
    remainders first, ties to the earlier mode). Needs len(mass) * min_count <= n."""
    extra = n - len(mass) * min_count
    share = extra * mass / mass.sum()
    counts = np.floor(share).astype(np.intp)
    left = extra - int(counts.sum())
    counts[np.argsort(-(share - counts), kind="stable")[:left]] += 1
    return counts + min_count


def resample_within(
    weights: NDArray,
    labels: NDArray[np.intp],
    resampler: Resampler,
    rng: np.random.Generator,
    *,
    min_count: int,
    min_mass: float,
    max_modes: int,
) -> tuple[NDArray[np.intp], NDArray[np.float64]]:
    """Resample each mode on its own (mixture tracking, `rafostrack.filtering.modes`): N ancestor
    indices and their normalised weights, mass(mode) / count(mode) for each of a mode's
    particles. Modes (labelled 0, 1, ... by decreasing mass) lighter than `min_mass` of the
    total are dropped, as are all but the `max_modes` heaviest; each kept mode gets at
    least `min_count` particles (`allocate`), so a light mode is not thinned out by chance.
    """
    n = len(weights)
    mass = np.bincount(labels, weights=weights)
    kept = min(int(np.sum(mass >= min_mass * mass.sum())), max_modes, n // min_count)
    kept = max(kept, 1)
    counts = allocate(mass[:kept], n, min_count)
    ancestors, new_weights = [], []
    for mode, count in enumerate(counts):
        members = np.flatnonzero(labels == mode)
        w = weights[members] / mass[mode]
        ancestors.append(members[resampler(w, rng, int(count))])
        new_weights.append(np.full(int(count), mass[mode] / count))
    out = np.concatenate(new_weights)
    return np.concatenate(ancestors), out / out.sum()
