"""Approximate Bayesian computation of a window's likelihood from a simulator of the window.

A simulating engine (`base.SimulatingEngine`): it never evaluates the factors w_ij, u_i.
For each particle X it simulates S windows from the model (`simulate_windows`: one window
of `rafostrack.sim.simulate`'s generative model, vectorised: each beacon detected with
probability Pd, arriving at mu + N(0, sigma^2) plus, with probability `multipath_fraction`,
a multipath delay (`model.measurement.multipath_delays`), and with probability `echo_fraction` a second
arrival (an echo) another such delay later, labelled with the same beacon;
Poisson(`clutter_rate`) clutter uniform on [0, W];
signals outside [0, W] lost; the float stores the earliest r), and compares each with the
stored TOAs T_1 < ... < T_K by a matching distance
    rho = min over partial matchings M of observed to simulated signals of
          sum_{(j,k) in M} (T_j - T~_k)^2 + g (#unmatched observed + #unmatched simulated),
with g = c^2 / 2 (`gap_s` = c: a pair farther apart than c is better left unmatched). For a
convex pair cost an optimal matching of two sorted sets never crosses, so rho is an edit
distance, computed by dynamic programming in O(K r) per simulation. With c = infinity
(`gap_s = 0`) only windows with K stored signals match, and rho is the squared Euclidean
distance between the sorted TOA vectors.

The ABC likelihood is a Gaussian kernel of bandwidth eps (`tolerance_s`) on rho:
    log L(X) = log (1/S) sum_s exp(-rho_s / (2 eps^2)) - K log(sqrt(2 pi) eps).
With c = infinity this is an unbiased estimate of the density of the stored TOAs convolved
with N(0, eps^2 I), which tends to the exact p(T | X) of `rafostrack.model.measurement` as eps -> 0 and
S -> infinity (tests/test_abc_engine.py). With finite c it is a pseudo-likelihood: observed
clutter, which no simulation reproduces, costs the same g for every particle instead of
zeroing every weight; it is no longer a density in T.

Label marginals: P(signal j from beacon i | X, T) is estimated by the kernel-weighted share
of the simulations whose optimal matching pairs observed signal j with a simulated signal
of beacon i (unmatched, or matched to simulated clutter: clutter).

Random draws: a Generator seeded with the window's entropy (the [filter] seed, the float
id, the window time; `base.WindowPrediction`) and `stream`, drawn in a fixed order
(detection uniforms, TOA normals, multipath uniforms and exponentials, echo uniforms and
exponentials, each (S, s);
clutter counts (S,); clutter times (S, max count)). They are common to all particles
(common random numbers): simulation s of every particle uses the same detection draws,
noise, delays and clutter, so that the weights of nearby particles differ by their
predictions, not by independent Monte Carlo noise, and a particle's estimate depends only
on its own state and the window, bit for bit, whichever other particles are evaluated
with it (a subset re-evaluated for smoothed labels gets the same values).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.special import logsumexp

from ..config import Config, ModelConfig
from ..model.measurement import multipath_delays
from .base import Association, WindowPrediction

LOG_SQRT_2PI = 0.5 * np.log(2.0 * np.pi)
NONE = -1  # label of an empty slot of a simulated window
_MATCH, _SKIP_OBSERVED, _SKIP_SIMULATED = 0, 1, 2
# Simulations per chunk, so that the DP tables (K + 1, r + 1, chunk) stay within ~64 MB.
_TABLE_BUDGET = 8_000_000


def simulate_windows(
    mu_s: NDArray,
    p_detect: NDArray,
    n_sims: int,
    *,
    model: ModelConfig,
    window_s: float,
    max_signals: int | None,
    rng: np.random.Generator,
) -> tuple[NDArray[np.float64], NDArray[np.intp]]:
    """S windows per particle (module docstring): stored TOAs (P, S, R) ascending, +inf in
    empty slots, and their labels (beacon column 0..s-1, s for clutter, -1 for empty).
    `max_signals` None stores every received signal (the unranked baseline)."""
    n, s = mu_s.shape
    shape = (n_sims, s)  # common random numbers: every particle's simulation s uses the same draws
    detected = rng.random(shape) < p_detect[:, None, :]
    toa = mu_s[:, None, :] + model.toa_sigma_s * rng.standard_normal(shape)
    delayed = rng.random(shape) < model.multipath_fraction
    toa = toa + np.where(delayed, multipath_delays(rng, model, shape), 0.0)
    echoed = rng.random(shape) < model.echo_fraction
    echo = toa + multipath_delays(rng, model, shape)
    received = detected & (toa >= 0.0) & (toa <= window_s)
    echo_received = received & echoed & (echo <= window_s)
    n_clutter = rng.poisson(model.clutter_rate, n_sims)
    most = int(n_clutter.max()) if n_clutter.size else 0
    clutter = rng.uniform(0.0, window_s, (n_sims, most))
    clutter = np.broadcast_to(np.where(np.arange(most) < n_clutter[:, None], clutter, np.inf), (n, n_sims, most))
    times = np.concatenate([np.where(received, toa, np.inf), np.where(echo_received, echo, np.inf), clutter], axis=-1)
    labels = np.concatenate([np.arange(s), np.arange(s), np.full(most, s)]).astype(np.intp)
    width = 2 * s + most if max_signals is None else min(max_signals, 2 * s + most)
    order = np.argsort(times, axis=-1, kind="stable")[..., :width]
    stored = np.take_along_axis(times, order, axis=-1)
    return stored, np.where(np.isfinite(stored), labels[order], NONE)


def align(
    toa_s: NDArray, sims: NDArray, gap_cost: float, *, traceback: bool = True
) -> tuple[NDArray[np.float64], NDArray[np.intp] | None]:
    """The matching distance rho (module docstring) between the observed TOAs (K,) and each
    simulated window (N, R) (+inf padding at the end), and, with `traceback`, the optimal
    matching: for each observed signal the slot of its simulated partner, or -1 (N, K).

    gap_cost = g per unmatched signal (inf: every signal must be matched)."""
    k, (n, r) = len(toa_s), sims.shape
    count = np.isfinite(sims).sum(axis=1)
    gap = np.arange(max(k, r) + 1) * gap_cost if np.isfinite(gap_cost) else np.r_[0.0, np.full(max(k, r), np.inf)]
    dist = np.empty((k + 1, r + 1, n))
    dist[0] = gap[: r + 1, None]
    dist[:, 0] = gap[: k + 1, None]
    choice = np.empty((k + 1, r + 1, n), dtype=np.int8) if traceback else None
    if choice is not None:
        choice[0], choice[:, 0], choice[0, 0] = _SKIP_SIMULATED, _SKIP_OBSERVED, _MATCH
    with np.errstate(invalid="ignore"):
        for i in range(1, k + 1):
            pair = (toa_s[i - 1] - sims) ** 2  # (N, R)
            for j in range(1, r + 1):
                options = np.stack(
                    [dist[i - 1, j - 1] + pair[:, j - 1], dist[i - 1, j] + gap_cost, dist[i, j - 1] + gap_cost]
                )
                best = np.argmin(options, axis=0)  # ties: match first
                dist[i, j] = np.take_along_axis(options, best[None], axis=0)[0]
                if choice is not None:
                    choice[i, j] = best
    cols = np.arange(n)
    rho = dist[k, count, cols]
    if choice is None:
        return rho, None
    match = np.full((n, k), -1, dtype=np.intp)
    row = np.full(n, k, dtype=np.intp)  # traceback position (observed, simulated)
    col = count.astype(np.intp)
    for _ in range(k + r):
        step = choice[row, col, cols]
        active = (row > 0) | (col > 0)
        pair_up = active & (step == _MATCH)
        match[cols[pair_up], row[pair_up] - 1] = col[pair_up] - 1
        row = row - (active & (step != _SKIP_SIMULATED))
        col = col - (active & (step != _SKIP_OBSERVED))
    return rho, match


@dataclass(frozen=True)
class ABCEngine:
    """The ABC likelihood and label marginals of a window (module docstring)."""

    tolerance_s: float = 2.0
    simulations: int = 32
    gap_s: float = 10.0  # c; 0 = infinity (only equal counts match)
    stream: int = 0

    @property
    def gap_cost(self) -> float:
        return np.inf if self.gap_s == 0 else 0.5 * self.gap_s**2

    def simulate(self, window: WindowPrediction, *, marginals: bool = True) -> Association:
        """log L(X) per particle and, unless `marginals=False`, the marginals (P, s, K)."""
        rng = np.random.default_rng([*window.entropy, self.stream])
        n, s = window.mu_s.shape
        k = len(window.toa_s)
        sims, labels = simulate_windows(
            window.mu_s, window.p_detect, self.simulations, model=window.model, window_s=window.window_s,
            max_signals=window.max_signals if window.ranked else None, rng=rng,
        )  # fmt: skip
        r = sims.shape[-1]
        flat = sims.reshape(n * self.simulations, r)
        chunk = max(1, _TABLE_BUDGET // ((k + 1) * (r + 1)))
        rho = np.empty(len(flat))
        match = np.empty((len(flat), k), dtype=np.intp)
        for lo in range(0, len(flat), chunk):
            part_rho, part_match = align(window.toa_s, flat[lo : lo + chunk], self.gap_cost, traceback=marginals)
            rho[lo : lo + chunk] = part_rho
            if part_match is not None:
                match[lo : lo + chunk] = part_match
        eps = self.tolerance_s
        log_kernel = -rho.reshape(n, self.simulations) / (2.0 * eps * eps) - k * (np.log(eps) + LOG_SQRT_2PI)
        with np.errstate(divide="ignore"):
            log_sum = logsumexp(log_kernel, axis=1)
        log_z = log_sum - np.log(self.simulations)
        if not marginals:
            return Association(log_z, np.full((n, s, k), np.nan))
        finite = np.isfinite(log_sum)
        weights = np.where(finite[:, None], np.exp(log_kernel - np.where(finite, log_sum, 0.0)[:, None]), 0.0)
        pairs = match.reshape(n, self.simulations, k)
        partner = np.take_along_axis(labels, np.clip(pairs, 0, None), axis=-1)
        partner = np.where(pairs >= 0, partner, s)  # unmatched: clutter
        p_match = np.einsum("nm,nmji->nij", weights, partner[..., None] == np.arange(s))
        return Association(log_z, p_match)


def from_config(config: Config) -> ABCEngine:
    """The ABC engine with the `[abc]` settings."""
    a = config.abc
    return ABCEngine(tolerance_s=a.tolerance_s, simulations=a.simulations, gap_s=a.gap_s, stream=a.stream)
