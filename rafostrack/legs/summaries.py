"""Posterior summaries of a leg chain: trajectory mean, MAP, credible bands, leg table.

- `position_samples`: x(t) for every kept sample, (S, n, 2);
- `mean_track`: the pointwise posterior mean E[x(t) | y] (ours; defined whatever K);
- `paper_estimate`: the paper's estimate, the trajectory of the chain's mean parameter
  vector (fixed K only: mean start, speeds, durations; circular mean of headings);
- `credible_band`: pointwise equal-tailed intervals of each coordinate;
- `leg_table`: the MAP's legs, each with credible intervals of its start and end (the
  nearest change time in every sample) and of its mean velocity over the MAP leg's span
  in every sample, (x(end) - x(start)) / (end - start), as speed and heading.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from .model import Legs
from .sampler import Chain
from .trajectory import mean_velocities, positions


def position_samples(chain: Chain, times: NDArray) -> NDArray[np.float64]:
    """(S, n, 2): every kept sample's positions at `times`."""
    return np.stack([positions(legs, times) for legs in chain.samples])


def velocity_samples(chain: Chain, starts: NDArray, ends: NDArray) -> NDArray[np.float64]:
    """(S, n, 2): every kept sample's mean velocity over [starts, ends]."""
    return np.stack([mean_velocities(legs, starts, ends) for legs in chain.samples])


def mean_track(chain: Chain, times: NDArray) -> NDArray[np.float64]:
    """(n, 2) posterior mean position at `times`."""
    return position_samples(chain, times).mean(axis=0)


def credible_band(samples: NDArray, level: float = 0.95) -> tuple[NDArray, NDArray]:
    """Pointwise equal-tailed interval (lower, upper) over the first axis."""
    tail = 0.5 * (1.0 - level)
    return np.quantile(samples, tail, axis=0), np.quantile(samples, 1.0 - tail, axis=0)


def circular_mean(angles: NDArray, axis: int = 0) -> NDArray:
    return np.arctan2(np.sin(angles).mean(axis=axis), np.cos(angles).mean(axis=axis))


def paper_estimate(chain: Chain) -> Legs:
    """The trajectory of the chain's mean parameters (paper section 5, step 6); fixed K only."""
    ks = {s.n_legs for s in chain.samples}
    if len(ks) != 1:
        raise ValueError("the chain's mean parameter vector needs a fixed number of legs")
    start = np.mean([s.knots[0] for s in chain.samples], axis=0)
    speeds = np.mean([s.speeds for s in chain.samples], axis=0)
    headings = circular_mean(np.array([s.headings for s in chain.samples]))
    durations = np.mean([s.durations[:-1] for s in chain.samples], axis=0)
    first = chain.samples[0]
    return Legs.from_parameters(start, first.cuts[0], first.cuts[-1], speeds, headings, durations)


def sample_ess(values: NDArray, batches: int = 20) -> NDArray[np.float64]:
    """Effective sample size of a chain (first axis) by batch means, per remaining element:
    n var(x) / (b var(batch means)), capped at n."""
    n = len(values)
    b = n // batches
    if b < 1 or n < 2 * batches:
        return np.full(values.shape[1:], float(n))
    means = values[: b * batches].reshape(batches, b, *values.shape[1:]).mean(axis=1)
    var = values.var(axis=0, ddof=1)
    var_means = means.var(axis=0, ddof=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        ess = np.where(var_means > 0, var / (b * var_means) * n, float(n))
    return np.minimum(ess, float(n))


@dataclass(frozen=True)
class LegRow:
    start: float
    start_lo: float
    start_hi: float
    end: float
    end_lo: float
    end_hi: float
    speed: float
    speed_lo: float
    speed_hi: float
    heading_rad: float
    heading_lo_rad: float
    heading_hi_rad: float


def leg_table(chain: Chain, legs: Legs | None = None, level: float = 0.95) -> pd.DataFrame:
    """One row per leg of `legs` (default: the MAP) with credible intervals (module docstring).
    Speeds in the data's length per time unit; headings in radians counter-clockwise from x."""
    legs = chain.best if legs is None else legs
    tail = 0.5 * (1.0 - level)
    starts, ends = legs.cuts[:-1], legs.cuts[1:]
    vel = velocity_samples(chain, starts, ends)  # (S, K, 2)
    speed = np.hypot(vel[..., 0], vel[..., 1])
    heading = np.arctan2(vel[..., 1], vel[..., 0])
    centre = np.arctan2(np.sin(heading).mean(axis=0), np.cos(heading).mean(axis=0))
    offset = (heading - centre + math.pi) % (2 * math.pi) - math.pi  # about the circular mean
    inner = legs.cuts[1:-1]
    nearest = np.full((len(chain.samples), len(inner)), np.nan)
    for s, sample in enumerate(chain.samples):
        cuts = sample.cuts[1:-1]
        if len(cuts) and len(inner):
            nearest[s] = cuts[np.abs(cuts[None, :] - inner[:, None]).argmin(axis=1)]
    with np.errstate(all="ignore"):
        cut_lo = np.nanquantile(nearest, tail, axis=0) if len(inner) else np.zeros(0)
        cut_hi = np.nanquantile(nearest, 1 - tail, axis=0) if len(inner) else np.zeros(0)
    start_lo = np.concatenate([[legs.cuts[0]], cut_lo])
    start_hi = np.concatenate([[legs.cuts[0]], cut_hi])
    end_lo = np.concatenate([cut_lo, [legs.cuts[-1]]])
    end_hi = np.concatenate([cut_hi, [legs.cuts[-1]]])
    rows = [
        LegRow(
            start=float(starts[i]),
            start_lo=float(start_lo[i]),
            start_hi=float(start_hi[i]),
            end=float(ends[i]),
            end_lo=float(end_lo[i]),
            end_hi=float(end_hi[i]),
            speed=float(speed[:, i].mean()),
            speed_lo=float(np.quantile(speed[:, i], tail)),
            speed_hi=float(np.quantile(speed[:, i], 1 - tail)),
            heading_rad=float(centre[i]),
            heading_lo_rad=float(centre[i] + np.quantile(offset[:, i], tail)),
            heading_hi_rad=float(centre[i] + np.quantile(offset[:, i], 1 - tail)),
        )
        for i in range(legs.n_legs)
    ]
    return pd.DataFrame([r.__dict__ for r in rows])
