"""The leg model (paper section 3) and its prior (section 4.1), held as knots.

A trajectory of K legs: leg i moves at constant speed w_i (length units per time unit)
and heading a_i (radians, counter-clockwise from the x axis) for a duration t_i, each leg
starting where and when the previous one ended (the paper's chaining constraints):

    x_{i+1} = x_i + w_i t_i (cos a_i, sin a_i).

`Legs` holds the same trajectory as its knots: the leg boundaries `cuts` (start time,
K - 1 change times, end time) and the positions there, `knots` (K + 1, 2). The last leg
runs to the end of the data, so its duration is implied: the K - 1 change times are the
free durations (paper: K durations, the last one unidentified beyond the data).

Prior, in the paper's leg coordinates theta = (x_0, w_1..K, a_1..K, t_1..K-1):
  - durations ~ U(t_min, t_max) (paper: U(5, 40) s), the legs a renewal process started
    at the first time: p(t_1..t_K-1) * P(t_K > r), r the last leg's part inside the data,
    which is also a proper prior on K (our reversible-jump sampler uses it);
  - speeds ~ N(mu_w, sd_w^2) truncated to w >= 0 (paper: N(12.5, 2^2));
  - first heading uniform on the circle, each next heading a_i - a_{i-1} ~ wrapped
    N(0, sd_a^2) (paper: sd_a = pi/12);
  - start x_0 flat (position fixes enter as observations).
In knot coordinates phi = (x_0..x_K, cuts) the density gains the Jacobian of
(w_i, a_i) -> x_i - x_{i-1} = w_i t_i (cos a_i, sin a_i), |det| = t_i^2 w_i per leg:
    log pi_knot(phi) = log pi_leg(theta(phi)) - sum_i log(t_i^2 w_i).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import NDArray
from scipy.special import log_ndtr

TWO_PI = 2.0 * math.pi


@dataclass(frozen=True)
class LegPrior:
    """The prior's parameters (defaults: the paper's, section 4.1; units of the data)."""

    speed_mean: float = 12.5
    speed_sd: float = 2.0
    heading_change_sd_rad: float = math.pi / 12.0
    duration_min: float = 5.0
    duration_max: float = 40.0

    def __post_init__(self) -> None:
        if not (0 <= self.duration_min < self.duration_max):
            raise ValueError(f"need 0 <= duration_min < duration_max, got {self.duration_min}, {self.duration_max}")
        if self.speed_sd <= 0 or self.heading_change_sd_rad <= 0:
            raise ValueError("speed_sd and heading_change_sd_rad must be > 0")


@dataclass(frozen=True)
class Legs:
    """A leg trajectory as knots: leg i runs from (cuts[i], knots[i]) to (cuts[i+1], knots[i+1])."""

    cuts: NDArray[np.float64]  # (K + 1,) strictly increasing
    knots: NDArray[np.float64]  # (K + 1, 2)

    @property
    def n_legs(self) -> int:
        return len(self.cuts) - 1

    # Derived per-leg quantities, computed once (the sampler asks for them often).
    @cached_property
    def durations(self) -> NDArray[np.float64]:
        return self.cuts[1:] - self.cuts[:-1]

    @cached_property
    def displacements(self) -> NDArray[np.float64]:
        return self.knots[1:] - self.knots[:-1]

    @cached_property
    def lengths(self) -> NDArray[np.float64]:
        d = self.displacements
        return np.hypot(d[:, 0], d[:, 1])

    @property
    def velocities(self) -> NDArray[np.float64]:
        """(K, 2) per-leg velocity."""
        return self.displacements / self.durations[:, None]

    @cached_property
    def speeds(self) -> NDArray[np.float64]:
        return self.lengths / self.durations

    @cached_property
    def headings(self) -> NDArray[np.float64]:
        d = self.displacements
        return np.arctan2(d[:, 1], d[:, 0])

    @staticmethod
    def from_parameters(
        start_xy: NDArray | tuple[float, float],
        start_time: float,
        end_time: float,
        speeds: NDArray,
        headings: NDArray,
        durations: NDArray,
    ) -> Legs:
        """Chain legs (paper section 3): K speeds and headings, the first K - 1 durations
        (the last leg runs to `end_time`). Raises ValueError when the legs do not fit."""
        speeds, headings = np.asarray(speeds, dtype=float), np.asarray(headings, dtype=float)
        durations = np.asarray(durations, dtype=float)
        if len(durations) != len(speeds) - 1 or len(headings) != len(speeds):
            raise ValueError("need K speeds and headings and K - 1 durations")
        cuts = np.empty(len(speeds) + 1)
        cuts[0], cuts[-1] = start_time, end_time
        cuts[1:-1] = start_time + np.cumsum(durations)
        tau = cuts[1:] - cuts[:-1]
        if np.any(tau <= 0):
            raise ValueError("leg boundaries must increase")
        knots = np.empty((len(speeds) + 1, 2))
        knots[0] = start_xy
        knots[1:, 0] = np.cumsum(speeds * tau * np.cos(headings))
        knots[1:, 1] = np.cumsum(speeds * tau * np.sin(headings))
        knots[1:] += knots[0]
        return Legs(cuts, knots)


def wrap_angle(angle: NDArray | float) -> NDArray:
    """Angle wrapped to [-pi, pi)."""
    return (np.asarray(angle) + math.pi) % TWO_PI - math.pi


def log_wrapped_normal(angle: NDArray, sd: float, wraps: int = 3) -> NDArray:
    """log density on the circle of N(0, sd^2) wrapped: log sum_k N(angle + 2 pi k; 0, sd^2)."""
    a = wrap_angle(angle)[..., None] + TWO_PI * np.arange(-wraps, wraps + 1)
    terms = -0.5 * (a / sd) ** 2
    top = terms.max(axis=-1)
    return np.asarray(top + np.log(np.exp(terms - top[..., None]).sum(axis=-1)) - math.log(sd * math.sqrt(TWO_PI)))


def log_duration_prior(cuts: NDArray, prior: LegPrior) -> float:
    """The renewal prior of the leg boundaries: prod_{i<K} U(t_i; t_min, t_max) * P(t > r),
    r the last leg's duration inside the data (module docstring)."""
    tau = cuts[1:] - cuts[:-1]
    width = prior.duration_max - prior.duration_min
    inner, last = tau[:-1], tau[-1]
    if np.any(inner < prior.duration_min) or np.any(inner > prior.duration_max) or last <= 0:
        return -math.inf
    survive = min(1.0, (prior.duration_max - last) / width)
    if survive <= 0:
        return -math.inf
    return -len(inner) * math.log(width) + math.log(survive)


def log_prior(legs: Legs, prior: LegPrior) -> float:
    """log pi_leg(theta): the prior density in the paper's leg coordinates (module docstring)."""
    lp = log_duration_prior(legs.cuts, prior)
    if lp == -math.inf:
        return lp
    w, a = legs.speeds, legs.headings
    z = (w - prior.speed_mean) / prior.speed_sd
    lp += float(np.sum(-0.5 * z**2 - math.log(prior.speed_sd * math.sqrt(TWO_PI))))
    lp -= len(w) * float(log_ndtr(prior.speed_mean / prior.speed_sd))  # truncation to w >= 0
    lp -= math.log(TWO_PI)
    if len(a) > 1:
        lp += float(np.sum(log_wrapped_normal(a[1:] - a[:-1], prior.heading_change_sd_rad)))
    return lp


def log_jacobian(legs: Legs) -> float:
    """log |d theta / d phi| = -sum_i log(t_i^2 w_i): add to log pi_leg for the knot density."""
    return -float(np.sum(np.log(legs.durations * np.maximum(legs.lengths, 1e-300))))  # t^2 w = t |d|


def sample_prior(
    prior: LegPrior, start_xy: NDArray | tuple[float, float], start_time: float, end_time: float,
    rng: np.random.Generator,
) -> Legs:  # fmt: skip
    """A trajectory drawn from the prior over [start_time, end_time] (renewal durations,
    truncated-normal speeds, wrapped-normal heading changes)."""
    durations: list[float] = []
    elapsed = 0.0
    while True:
        tau = rng.uniform(prior.duration_min, prior.duration_max)
        if elapsed + tau >= end_time - start_time:
            break
        durations.append(tau)
        elapsed += tau
    k = len(durations) + 1
    speeds = np.empty(k)
    for i in range(k):  # truncated normal by rejection (the prior mass below 0 is small)
        draw = -1.0
        while draw < 0:
            draw = rng.normal(prior.speed_mean, prior.speed_sd)
        speeds[i] = draw
    first = rng.uniform(-math.pi, math.pi)
    headings = first + np.concatenate([[0.0], np.cumsum(rng.normal(0.0, prior.heading_change_sd_rad, k - 1))])
    return Legs.from_parameters(start_xy, start_time, end_time, speeds, wrap_angle(headings), np.array(durations))
