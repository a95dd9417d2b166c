"""Two-filter smoothing: the forward filter and a filter run back from the end fix, joined.

Why: FFBSm (`rafostrack.smoothing.ffbsm`) reweights the forward filter's particles, so where the
forward filter lost the float for a few windows (two sources heard, a fast eddy, clutter
that fits a mirror position) no weighting brings back a position it never held. A second
particle filter, run from the end (recovery) fix towards the launch with the drift
reversed (`MotionModel.reversed`), holds the float there when the later data do. The
smoothed marginal is estimated on the particles of both filters, each weighted by the
generalised two-filter formula (Briers, Doucet & Maskell 2010, Ann. Inst. Stat. Math. 62),
and the two sets are pooled by the evidence each gives.

Maths. Windows k = 1..K lie between the launch fix (k = 0) and the end fix (k = K + 1);
f is the drift's transition density and gamma its invariant law
(`MotionModel.log_invariant_density`: flat in position, the stationary velocity), under
which the drift is reversible. The backward filter, started from gamma x N(end fix) and
moved with the reversed drift, then targets gamma(x) p(y_k..y_K, end | x_k = x) / Z^b_k. With

    P_k(x) = sum_i W^f_{k-1,i} f(x | x^f_{k-1,i})                          (forward prediction)
    B_k(x) = sum_j W^b_{k+1,j} f(x^b_{k+1,j} | x) / gamma(x^b_{k+1,j})   (p(y_k+1.., end | x) / Z^b_k+1)

the smoothed marginal is pi_k(x) proportional to P_k(x) L_k(x) B_k(x). The forward particles
at k sample P_k L_k / exp(l^f_k) and the backward ones gamma L_k B_k / exp(l^b_k), with l^f_k
and l^b_k the two filters' step evidences, so each filter's particles estimate pi_k by the
two-filter formula, with weights

    forward:   omega(x) = W^f_k(x) exp(l^f_k) B_k(x)
    backward:  omega(x) = W^b_k(x) exp(l^b_k) P_k(x) / gamma(x),

whose sums both estimate the same integral of P_k L_k B_k. Normalised together over the
union, the two estimates are pooled in proportion to those sums: equally where both filters
hold the float, while a filter that lost it (its particles where the data do not put the
float: a low step evidence, and only the drift's jump component joining them to the other
filter's cloud) gives way to the other. (Pooling by the balance heuristic of multiple
importance sampling instead would divide by each filter's proposal density, normalised by
its own evidence, in both filters' weights: a lost filter's low evidence would then bias
the healthy filter's weights too.)

Cost per window O(C M): M = `ffbsm.MAX_ROWS` quantile points of each neighbouring cloud
stand for it in P_k and B_k, and each filter's cloud at k enters as at most C =
`JOIN_COLUMNS` quantile points of its weights (the union then has no more points than one
filter's cloud, whatever the particle count, and the smoothed labels and summaries cost no
more than FFBSm's). As in `ffbsm.smooth`, each
particle stands for a Gaussian kernel of covariance h^2 Sigma (regularised).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..domain import Cloud, Particles, days_between
from ..filtering.resampling import quantile_points
from ..motion import LinearGaussian, MotionModel
from .ffbsm import (
    MAX_ROWS,
    PRUNE,
    Smoothed,
    cloud_covariance,
    column_points,
    plane_states,
    regularised,
    silverman_bandwidth,
    whitened,
)
from .ffbsm_kernel import log_mixture_density

# Each filter's cloud at a window enters the join as at most this many quantile points.
JOIN_COLUMNS = 512


def forward_view(clouds: Sequence[Cloud]) -> list[Cloud]:
    """A backward filter's clouds (latest first, velocities as it moved them: negated) in
    time order, with velocities as the forward drift has them."""
    return [Cloud(c.time, c.particles.reversed(), c.weights) for c in reversed(clouds)]


@dataclass(frozen=True)
class _Neighbour:
    """A neighbouring cloud as the mixture that stands for it: quantile points, their log
    weights, and the regularised transition between it and the window; `before`: the
    cloud at the window before (origins of the transition: P_k), else after (B_k)."""

    cloud: Cloud
    index: NDArray[np.intp]
    log_weights: NDArray[np.float64]
    components: list[tuple[float, LinearGaussian]]
    before: bool


def _neighbour(
    cloud: Cloud, time: np.datetime64, motion: MotionModel, spread: NDArray, *, before: bool, max_rows: int
) -> _Neighbour:
    """The cloud before the window (its prediction P_k) or after it (B_k, weights / gamma)."""
    index, weights = quantile_points(cloud.weights, max_rows, PRUNE)
    log_weights = np.log(weights)
    dt_days = abs(days_between(cloud.time, time))
    (first, kernel), *rest = motion.components(dt_days)
    if before:
        components = [(first, regularised(kernel, spread)), *rest]
    else:
        components = [(first, regularised(kernel, spread, at_destination=True)), *rest]
        log_weights = log_weights - motion.log_invariant_density(cloud.particles.take(index))
    return _Neighbour(cloud, index, log_weights, components, before)


def _log_density(near: _Neighbour, points: NDArray, ref: tuple[float, float]) -> NDArray:
    """log P_k (neighbour before: its particles are the origins) or log B_k (after: the
    destinations) at the window's points (tangent-plane states about `ref`)."""
    states = plane_states(near.cloud, near.index, *ref)
    origins, destinations = (states, points) if near.before else (points, states)
    za, zb, log_norm = whitened(near.components, origins, destinations)
    if near.before:  # sum over origins i, one value per destination j
        return log_mixture_density(za, zb, log_norm, near.log_weights)
    return log_mixture_density(zb, za, log_norm, near.log_weights)  # over destinations: roles swapped


def join_window(
    before: _Neighbour,
    forward: Cloud,
    backward: Cloud,
    after: _Neighbour,
    log_evidence: tuple[float, float],
    motion: MotionModel,
    max_columns: int = JOIN_COLUMNS,
) -> Cloud:
    """The smoothed marginal at one window on the particles of both filters (module
    docstring): their union and its weights omega, normalised together. `log_evidence`:
    the forward and backward filters' step evidences at the window."""
    fwd, _ = column_points(forward, max_columns)
    bwd, _ = column_points(backward, max_columns)
    heaviest = int(np.argmax(fwd.weights))
    ref = (float(fwd.lat[heaviest]), float(fwd.lon[heaviest]))
    # Each filter's particles need the other filter's neighbour only: B_k at the forward
    # particles, P_k at the backward ones.
    log_b = _log_density(after, plane_states(fwd, np.arange(len(fwd.weights)), *ref), ref)
    log_p = _log_density(before, plane_states(bwd, np.arange(len(bwd.weights)), *ref), ref)
    l_f, l_b = log_evidence
    with np.errstate(divide="ignore"):
        log_omega = np.concatenate(
            [
                np.log(fwd.weights) + l_f + log_b,
                np.log(bwd.weights) + l_b + log_p - motion.log_invariant_density(bwd.particles),
            ]
        )
    log_omega = np.where(np.isfinite(log_omega), log_omega, -np.inf)
    weights = np.exp(log_omega - log_omega.max())
    union = Particles.concat([fwd.particles, bwd.particles])
    return Cloud(forward.time, union, weights / weights.sum())


def two_filter_smooth(
    forward: Sequence[Cloud],
    forward_loglik: Sequence[float],
    backward: Sequence[Cloud],
    backward_loglik: Sequence[float],
    motion: MotionModel,
    *,
    regularise: bool = True,
    max_columns: int = JOIN_COLUMNS,
    max_rows: int = MAX_ROWS,
    windows: range | None = None,
) -> tuple[list[Cloud], Smoothed]:
    """Smoothed marginals of windows 1..K (module docstring) on both filters' particles.

    `forward`: the forward filter's prior about the launch fix, then its clouds at the K
    windows; `backward`: the backward filter's clouds at the K windows, then its prior about
    the end fix, all in time order with forward velocities (`forward_view`). The log
    evidences are each filter's at the K windows (nan: a skipped step, counted as 0).
    Returns the K union clouds with their smoothed weights, and the same as `Smoothed`
    (weights, and the kernel covariance each particle stands for); of `windows` only (indices
    0..K-1) when given: each window's join is its own, the same bits whichever others are
    joined."""
    n_windows = len(forward) - 1
    if len(backward) != n_windows + 1 or len(forward_loglik) != n_windows or len(backward_loglik) != n_windows:
        raise ValueError("forward and backward filters must cover the same windows")
    # Each filter's kernels by its own particle count (its prior's: the filters' later clouds
    # come as quantile points); the backward filter may have fewer particles.
    h2 = silverman_bandwidth(len(forward[0].weights), motion.dim) ** 2 if regularise else 0.0
    h2_back = silverman_bandwidth(len(backward[-1].weights), motion.dim) ** 2 if regularise else 0.0
    clouds, kernels = [], []
    for k in range(n_windows) if windows is None else windows:
        now = forward[k + 1]
        if backward[k].time != now.time:
            raise ValueError(f"backward filter at {backward[k].time}, forward at {now.time}")
        spread_before, spread_after = h2 * cloud_covariance(forward[k]), h2_back * cloud_covariance(backward[k + 1])
        before = _neighbour(forward[k], now.time, motion, spread_before, before=True, max_rows=max_rows)
        after = _neighbour(backward[k + 1], now.time, motion, spread_after, before=False, max_rows=max_rows)
        evidence = (float(np.nan_to_num(forward_loglik[k])), float(np.nan_to_num(backward_loglik[k])))
        joined = join_window(before, now, backward[k], after, evidence, motion, max_columns)
        clouds.append(joined)
        kernels.append(h2 * cloud_covariance(joined)[:2, :2])
    return clouds, Smoothed([c.weights for c in clouds], kernels)
