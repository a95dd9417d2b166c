"""One tracking step's prior pi_0, the ABC-RW pseudo-likelihood f, and the ABC distance.

At time t every algorithm of the paper draws from pi_0(x^_{t-1}, v^_{t-1}) "using eq. 1",
given the previous step's point estimates. With v_t the velocity of the step to x_t
(`rafostrack.sensors.sensors`), the parameter of a step is theta = v_t (Nt x 2), and
    theta ~ N(v^_{t-1}, sigma^2 I),     x_t = x^_{t-1} + theta.

ABC-RW's f (section 3.3) "is based on the consecutive bearings and distances": the paper
gives no formula. We take, per target, Gaussians on the change of bearing and of step
length between the previous estimated step v^_{t-1} and this step theta,
    log f = sum_j -(d bearing_j)^2 / (2 s_b,j^2) - (|theta_j| - |v^_{t-1,j}|)^2 / (2 s_d^2),
with the scales that eq. 1 itself implies, times `f_scale`: s_d = f_scale sigma and
s_b,j = f_scale sigma / max(|v^_{t-1,j}|, sigma).

The ABC distance (eq. 10) is rho(c~, c) = ||c~ - c||_2^2 between simulated and observed
count vectors.

Arrays carry a chain axis: states (B, C, Nt, 2) for B independent scenarios and C chains;
draws (n, B, C, Nt, 2).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .sensors import simulate_counts

# Simulated (draw, scenario, chain, sensor, target) bits per chunk when computing distances.
_CHUNK_BITS = 2_000_000


@dataclass(frozen=True)
class StepPrior:
    """pi_0 of one step for B scenarios: theta ~ N(v_prev, sd^2 I), x_t = x_prev + theta."""

    x_prev: NDArray[np.float64]  # (B, Nt, 2)
    v_prev: NDArray[np.float64]  # (B, Nt, 2)
    sd: float

    def sample(self, n: int, chains: int, rng: np.random.Generator) -> NDArray[np.float64]:
        """n draws per scenario and chain, (n, B, C, Nt, 2)."""
        b, nt, _ = self.v_prev.shape
        return self.v_prev[None, :, None] + self.sd * rng.standard_normal((n, b, chains, nt, 2))

    def log_density(self, theta: NDArray) -> NDArray[np.float64]:
        """log pi_0(theta) up to a constant, summed over targets; theta (..., B, C, Nt, 2)."""
        z = (theta - self.v_prev[:, None]) / self.sd
        return np.asarray(-0.5 * (z * z).sum(axis=(-2, -1)))

    def positions(self, theta: NDArray) -> NDArray[np.float64]:
        """x_t = x_prev + theta for theta (..., B, C, Nt, 2)."""
        return np.asarray(self.x_prev[:, None] + theta)


def log_pseudo_likelihood(theta: NDArray, v_prev: NDArray, sd: float, f_scale: float = 1.0) -> NDArray[np.float64]:
    """log f(theta) of ABC-RW (module docstring); theta (..., B, C, Nt, 2), v_prev (B, Nt, 2)."""
    prev = v_prev[:, None]  # (B, 1, Nt, 2)
    cross = prev[..., 0] * theta[..., 1] - prev[..., 1] * theta[..., 0]
    dot = (prev * theta).sum(axis=-1)
    turn = np.arctan2(cross, dot)
    speed_prev = np.hypot(prev[..., 0], prev[..., 1])
    speed = np.hypot(theta[..., 0], theta[..., 1])
    s_d = f_scale * sd
    s_b = f_scale * sd / np.maximum(speed_prev, sd)
    return np.asarray((-0.5 * (turn / s_b) ** 2 - 0.5 * ((speed - speed_prev) / s_d) ** 2).sum(axis=-1))


def distances(
    theta: NDArray,
    prior: StepPrior,
    counts: NDArray,
    sensors: NDArray,
    p_correct: float,
    rng: np.random.Generator,
) -> NDArray[np.float64]:
    """rho(c~, c) (eq. 10) for every draw: simulate the network's counts for (x_t, theta)
    and compare with the observed `counts` (B, Ns); theta (n, B, C, Nt, 2) -> (n, B, C).
    Simulated in chunks of draws (the draws' random numbers are taken chunk by chunk)."""
    n = theta.shape[0]
    per_draw = int(np.prod(theta.shape[1:-1])) * len(sensors)
    step = max(1, _CHUNK_BITS // max(per_draw, 1))
    out = np.empty(theta.shape[:-2])
    obs = counts[:, None, :]  # (B, 1, Ns)
    for lo in range(0, n, step):
        th = theta[lo : lo + step]
        sim = simulate_counts(prior.positions(th), th, sensors, p_correct, rng)
        diff = sim - obs
        out[lo : lo + step] = np.einsum("...i,...i->...", diff, diff)
    return out
