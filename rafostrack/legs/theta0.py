"""The data-driven starting point theta_0 (paper section 4.3).

For each guess k of the number of legs (paper: k in {5, 10, ..., 50}): k legs of equal
duration T / k; each leg's heading and speed from the two measurements nearest in time to
its start and its end (ties between guesses go to the fewer legs),
    a_i = atan2(y_k - y_j),  w_i = |y_k - y_j| / t_i,
the legs chained from the measurement nearest the start time. Keep the k whose trajectory
scores best (the paper's summed distance by default). Guesses whose equal durations lie
outside the prior's duration range have prior density 0 and are skipped (unless none fits,
then the nearest is used).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import NDArray

from .model import LegPrior, Legs, log_duration_prior
from .scores import Measurements, paper_score
from .trajectory import positions

PAPER_LEG_COUNTS = tuple(range(5, 55, 5))


def equal_legs(data: Measurements, k: int, start_time: float | None = None, end_time: float | None = None) -> Legs:
    """theta_0 for one guess k: equal durations, displacements between the measurements
    nearest in time to each leg's ends (module docstring)."""
    t0 = float(data.times[0] if start_time is None else start_time)
    t1 = float(data.times[-1] if end_time is None else end_time)
    cuts = np.linspace(t0, t1, k + 1)
    nearest = _nearest_index(data.times, cuts)
    step = np.diff(data.xy[nearest], axis=0)
    knots = data.xy[nearest[0]] + np.vstack([[0.0, 0.0], np.cumsum(step, axis=0)])
    return Legs(cuts, knots)


def data_driven_start(
    data: Measurements,
    prior: LegPrior,
    leg_counts: Sequence[int] = PAPER_LEG_COUNTS,
    score: Callable[[NDArray, NDArray], float] = paper_score,
    start_time: float | None = None,
    end_time: float | None = None,
    objective: Callable[[Legs], float] | None = None,
) -> Legs:
    """The best-scoring equal-duration guess over `leg_counts` (module docstring); with
    `objective` (lower is better, e.g. minus the log posterior), that ranks the guesses
    instead of the score."""
    t0 = float(data.times[0] if start_time is None else start_time)
    t1 = float(data.times[-1] if end_time is None else end_time)
    span = t1 - t0
    valid = [k for k in leg_counts if k >= 1 and log_duration_prior(np.linspace(t0, t1, k + 1), prior) > -np.inf]
    if not valid:  # no guess fits the prior: the count whose duration is nearest the prior's range
        mid = 0.5 * (prior.duration_min + prior.duration_max)
        valid = [max(1, math.ceil(span / mid))]
    best: tuple[float, Legs] | None = None
    for k in valid:
        legs = equal_legs(data, k, t0, t1)
        s = objective(legs) if objective is not None else score(positions(legs, data.times), data.xy)
        if best is None or s < best[0] - 1e-9 * (1.0 + abs(best[0])):  # near-ties: the fewer legs
            best = (s, legs)
    assert best is not None
    return best[1]


def _nearest_index(times: NDArray, targets: NDArray) -> NDArray[np.intp]:
    """Index of the time nearest each target (ties to the earlier)."""
    right = np.clip(np.searchsorted(times, targets), 1, len(times) - 1)
    left = right - 1
    if len(times) == 1:
        return np.zeros(len(targets), dtype=np.intp)
    pick_left = np.abs(targets - times[left]) <= np.abs(times[right] - targets)
    return np.where(pick_left, left, right)
