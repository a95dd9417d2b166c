"""The binary-sensor multi-target tracking paper (Ickowicz, "Approximate Bayesian algorithms
for multiple target tracking with binary sensors"): its sensor network and simulator
(`sensors`), one step's prior, pseudo-likelihood and ABC distance (`prior`), the ABC-Rej,
ABC-RW, ABC-PT and exact-likelihood MCMC steps (`samplers`) and the tracking loop with its
scores (`tracking`). The experiments are `papers.abc`.
"""

from .sensors import Truth, approaching, log_likelihood, sensor_grid, simulate_counts, simulate_truth
from .tracking import ALGORITHMS, NAMES, Settings, TrackResult, initial_estimates, rmse, track

__all__ = [
    "ALGORITHMS",
    "NAMES",
    "Settings",
    "TrackResult",
    "Truth",
    "approaching",
    "initial_estimates",
    "log_likelihood",
    "rmse",
    "sensor_grid",
    "simulate_counts",
    "simulate_truth",
    "track",
]
