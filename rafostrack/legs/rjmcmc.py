"""Reversible-jump moves over the number of legs K (ours; the paper fixes K at theta_0's).

In knot coordinates (model docstring) a split and a merge are each other's reverse:

- split (K -> K + 1), chosen with probability b_K: pick leg i uniformly (1/K), a new
  change time u ~ U(c_i, c_{i+1}) (density 1/t_i), and a new knot at the trajectory's
  position there plus a kink v ~ N(0, s^2 I). The map (phi, u, v) -> phi' is a shear:
  |Jacobian| = 1.
- merge (K -> K - 1), chosen with probability d_K: pick one of the K - 1 inner change
  times uniformly and remove it with its knot; v is that knot's offset from the merged
  leg's straight line.

Acceptance ratio of a split (a merge's is its inverse):
    pi_knot(phi') / pi_knot(phi) * d_{K+1} / (b_K t_i N(v; 0, s^2 I)),
the 1/K of choosing the leg and of choosing the change time to remove cancelling. b_K =
d_K = 1/2, except b_1 = 1, d_1 = 0 and b_max = 0, d_max = 1. The prior on K is the renewal
prior of the durations (model docstring).
"""

from __future__ import annotations

import math

import numpy as np

from .model import Legs

Proposal = tuple[Legs, float, str, float, float]


def split_probability(n_legs: int, max_legs: int) -> float:
    """b_K: the probability that a jump move tries a split."""
    if n_legs <= 1:
        return 1.0
    if n_legs >= max_legs:
        return 0.0
    return 0.5


def merge_probability(n_legs: int, max_legs: int) -> float:
    """d_K = 1 - b_K."""
    return 1.0 - split_probability(n_legs, max_legs)


def log_kink_density(v: np.ndarray, sd: float) -> float:
    """log N(v; 0, sd^2 I) in two dimensions."""
    return float(-0.5 * (v @ v) / sd**2 - math.log(2.0 * math.pi * sd**2))


def split(legs: Legs, rng: np.random.Generator, kink_sd: float, max_legs: int) -> Proposal | None:
    """Split a uniformly chosen leg at a uniform time (module docstring)."""
    k = legs.n_legs
    if k >= max_legs:
        return None
    i = int(rng.integers(k))
    c0, c1 = float(legs.cuts[i]), float(legs.cuts[i + 1])
    u = rng.uniform(c0, c1)
    if not (c0 < u < c1):
        return None
    v = rng.normal(0.0, kink_sd, 2)
    on_line = legs.knots[i] + (u - c0) / (c1 - c0) * (legs.knots[i + 1] - legs.knots[i])
    cuts = np.insert(legs.cuts, i + 1, u)
    knots = np.insert(legs.knots, i + 1, on_line + v, axis=0)
    log_q = (
        math.log(merge_probability(k + 1, max_legs))
        - math.log(split_probability(k, max_legs))
        + math.log(c1 - c0)
        - log_kink_density(v, kink_sd)
    )
    return Legs(cuts, knots), log_q, "knot", c0, c1


def merge(legs: Legs, rng: np.random.Generator, kink_sd: float, max_legs: int) -> Proposal | None:
    """Remove a uniformly chosen inner change time and its knot (module docstring)."""
    k = legs.n_legs
    if k <= 1:
        return None
    j = int(rng.integers(1, k))
    c0, c, c1 = (float(x) for x in legs.cuts[j - 1 : j + 2])
    on_line = legs.knots[j - 1] + (c - c0) / (c1 - c0) * (legs.knots[j + 1] - legs.knots[j - 1])
    v = legs.knots[j] - on_line
    log_q = (
        math.log(split_probability(k - 1, max_legs))
        - math.log(merge_probability(k, max_legs))
        - math.log(c1 - c0)
        + log_kink_density(v, kink_sd)
    )
    return Legs(np.delete(legs.cuts, j), np.delete(legs.knots, j, axis=0)), log_q, "knot", c0, c1
