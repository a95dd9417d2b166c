"""Positions and velocities along a leg trajectory at any times (vectorised).

Inside leg i (cuts[i] <= t < cuts[i+1]) the position is the linear interpolation of its
knots, x(t) = x_i + (t - c_i) / (c_{i+1} - c_i) (x_{i+1} - x_i); before the start or after
the end the first or last leg is extended (constant velocity).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .model import Legs


def leg_index(cuts: NDArray, times: NDArray) -> NDArray[np.intp]:
    """The leg each time falls in (0..K-1; times outside go to the first or last leg)."""
    return np.clip(np.searchsorted(cuts, times, side="right") - 1, 0, len(cuts) - 2)


def positions(legs: Legs, times: NDArray) -> NDArray[np.float64]:
    """(n, 2) positions at `times`."""
    times = np.asarray(times, dtype=float)
    i = leg_index(legs.cuts, times)
    c0, c1 = legs.cuts[i], legs.cuts[i + 1]
    frac = (times - c0) / (c1 - c0)
    return legs.knots[i] + frac[:, None] * (legs.knots[i + 1] - legs.knots[i])


def velocities(legs: Legs, times: NDArray) -> NDArray[np.float64]:
    """(n, 2) velocities at `times` (the velocity of the leg each falls in)."""
    return legs.velocities[leg_index(legs.cuts, np.asarray(times, dtype=float))]


def mean_velocities(legs: Legs, starts: NDArray, ends: NDArray) -> NDArray[np.float64]:
    """(n, 2) mean velocity over each interval [start, end]: (x(end) - x(start)) / (end - start)."""
    starts, ends = np.asarray(starts, dtype=float), np.asarray(ends, dtype=float)
    return (positions(legs, ends) - positions(legs, starts)) / (ends - starts)[:, None]
