"""Track the targets over the T steps with one of the paper's algorithms, and score it.

At t = 1..T the chosen step (`samplers`) is run from pi_0(x^_{t-1}, v^_{t-1}) on the
counts c_t, giving v^_t and x^_t = x^_{t-1} + v^_t (section 3, Algs. ABC-Rej / ABC-RW).
The start (x^_0, v^_0) is the truth plus Gaussian errors (`initial_estimates`; the paper
says only that the start was "known within a range of 10 meters" for Fig. 3).

Tolerances. The paper's rule (section 3.4) epsilon = Ns (pe Nt)^2, with pe there the
error probability, is `paper_tolerance`; with sensor errors in both the data and the
simulations it is far below the distance even the true state gives (its acceptance is ~0),
so by default we use `expected_distance`: E[rho] at the true state,
2 Ns Nt pe (1 - pe), the distance a correct draw has on average.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from .prior import StepPrior
from .samplers import StepResult, abc_chain_step, mcmc_step, rejection_step, tolerance_ladder
from .sensors import VELOCITY_VAR, Truth

ALGORITHMS = ("rej", "rw", "pt", "mcmc")
NAMES = {"rej": "ABC-Rej", "rw": "ABC-RW", "pt": "ABC-PT", "mcmc": "MCMC (exact likelihood)"}


def paper_tolerance(n_sensors: int, n_targets: int, p_correct: float) -> float:
    """The paper's epsilon = Ns (p_error Nt)^2 (section 3.4)."""
    return float(n_sensors * ((1.0 - p_correct) * n_targets) ** 2)


def expected_distance(n_sensors: int, n_targets: int, p_correct: float) -> float:
    """E[rho(c~, c)] at the true state: each count is a sum of Nt bits flipped with
    probability 1 - pe, so c~_i - c_i has variance 2 Nt pe (1 - pe) and mean 0."""
    return float(2.0 * n_sensors * n_targets * p_correct * (1.0 - p_correct))


@dataclass(frozen=True)
class Settings:
    """An algorithm and its tuning. `tolerance` None: `expected_distance`."""

    algorithm: str
    particles: int = 300  # draws (Rej) or iterations per chain (RW, PT, MCMC) per step
    p_correct: float = 0.95
    velocity_var: float = VELOCITY_VAR
    tolerance: float | None = None
    chains: int = 5  # ABC-PT
    ladder_ratio: float = float(np.sqrt(2.0))  # ABC-PT: epsilon_{c+1} / epsilon_c
    swaps: int | None = None  # ABC-PT swap proposals per iteration (None: one per chain)
    f_scale: float = 1.0
    proposal_sd: float = 0.3  # MCMC random-walk sd per coordinate (units/s): ~22% accepted for Fig. 2
    keep: int = 0  # states kept per step for pictures

    def __post_init__(self) -> None:
        if self.algorithm not in ALGORITHMS:
            raise ValueError(f"algorithm must be one of {', '.join(ALGORITHMS)}, got {self.algorithm!r}")

    def tolerance_for(self, n_sensors: int, n_targets: int) -> float:
        if self.tolerance is not None:
            return self.tolerance
        return expected_distance(n_sensors, n_targets, self.p_correct)

    def simulations_per_step(self) -> int:
        """Model runs per scenario and step (the exact MCMC runs none: it evaluates eq. 6)."""
        return {"rej": self.particles, "rw": self.particles, "pt": self.particles * self.chains, "mcmc": 0}[
            self.algorithm
        ]


@dataclass
class TrackResult:
    """Estimates (R, T + 1, Nt, 2) and per-step diagnostics (R, T)."""

    x_hat: NDArray[np.float64]
    v_hat: NDArray[np.float64]
    acceptance: NDArray[np.float64]
    fallback: NDArray[np.bool_]
    seconds: float
    tolerance: float
    swap_acceptance: NDArray[np.float64] | None = None
    samples: list[NDArray[np.float64]] = field(default_factory=list)  # per t: positions (R, k, Nt, 2)


def initial_estimates(
    truth: Truth, rng: np.random.Generator, position_sd: float = 1.0, velocity_sd: float = 0.3
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(x^_0, v^_0): the true start with N(0, sd^2) errors per coordinate."""
    x0, v0 = truth.x[:, 0], truth.v[:, 0]
    return x0 + position_sd * rng.standard_normal(x0.shape), v0 + velocity_sd * rng.standard_normal(v0.shape)


def run_step(
    settings: Settings, prior: StepPrior, counts: NDArray, sensors: NDArray, tolerance: float, rng: np.random.Generator
) -> StepResult:
    """One step of the configured algorithm."""
    s = settings
    if s.algorithm == "rej":
        return rejection_step(
            prior, counts, sensors, s.p_correct, draws=s.particles, tolerance=tolerance, rng=rng, keep=s.keep
        )
    if s.algorithm == "mcmc":
        return mcmc_step(
            prior, counts, sensors, s.p_correct, iterations=s.particles, proposal_sd=s.proposal_sd, rng=rng, keep=s.keep
        )
    if s.algorithm == "rw":
        ladder, swaps = np.array([tolerance]), 0
    else:
        ladder = tolerance_ladder(tolerance, s.chains, s.ladder_ratio)
        swaps = s.chains if s.swaps is None else s.swaps
    return abc_chain_step(
        prior, counts, sensors, s.p_correct, iterations=s.particles, tolerances=ladder, swaps=swaps,
        f_scale=s.f_scale, rng=rng, keep=s.keep,
    )  # fmt: skip


def track(
    truth: Truth,
    sensors: NDArray,
    x0_hat: NDArray,
    v0_hat: NDArray,
    settings: Settings,
    rng: np.random.Generator,
) -> TrackResult:
    """Run the algorithm over every step of every scenario of `truth` (module docstring)."""
    started = time.perf_counter()
    n_rep, n_targets = x0_hat.shape[0], x0_hat.shape[1]
    steps = truth.steps
    tolerance = settings.tolerance_for(len(sensors), n_targets)
    x_hat = np.empty((n_rep, steps + 1, n_targets, 2))
    v_hat = np.empty_like(x_hat)
    x_hat[:, 0], v_hat[:, 0] = x0_hat, v0_hat
    acceptance = np.empty((n_rep, steps))
    fallback = np.empty((n_rep, steps), dtype=bool)
    swaps = np.empty((n_rep, steps)) if settings.algorithm == "pt" else None
    samples = []
    sd = float(np.sqrt(settings.velocity_var))
    for t in range(1, steps + 1):
        prior = StepPrior(x_hat[:, t - 1], v_hat[:, t - 1], sd)
        result = run_step(settings, prior, truth.counts[:, t], sensors, tolerance, rng)
        v_hat[:, t] = result.v_hat
        x_hat[:, t] = x_hat[:, t - 1] + result.v_hat
        acceptance[:, t - 1] = result.acceptance
        fallback[:, t - 1] = result.fallback
        if swaps is not None and result.swap_acceptance is not None:
            swaps[:, t - 1] = result.swap_acceptance
        if result.samples is not None:
            samples.append(x_hat[:, t - 1, None] + result.samples)
    return TrackResult(x_hat, v_hat, acceptance, fallback, time.perf_counter() - started, tolerance, swaps, samples)


def rmse(x_hat: NDArray, x_true: NDArray) -> NDArray[np.float64]:
    """Position RMSE over targets, per scenario and time: sqrt(mean_j |x^_t^j - x_t^j|^2),
    shape (R, T + 1). Target j's estimate is compared with target j (the prior carries
    each target's identity from step to step)."""
    return np.sqrt(((x_hat - x_true) ** 2).sum(axis=-1).mean(axis=-1))
