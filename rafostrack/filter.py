"""The particle filter over float position with per-window evidence (paper Alg. 1).

For each observation in time order: move the particles with the motion model over the
interval since the previous one (one exact transition, however long the gap), weight
each by the observation's likelihood (a window's arrival times, or a position fix), keep
the weighted cloud and the association marginals averaged over it, then resample when
the effective sample size drops below the threshold. The launch fix is the prior. Weights
stay in log space throughout.

The filter is assembled from components (`rafostrack.motion`, `rafostrack.likelihoods`,
`rafostrack.resampling`) and knows nothing else about them; its counts and warnings come
back in a `FilterResult`.
"""

from __future__ import annotations

import zlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .domain import Cloud, PositionFix, Window, days_between
from .likelihoods import ArrivalLikelihood, Evidence, Likelihood
from .motion import MotionModel
from .resampling import Resampler, ess, normalise_log_weights

Observation = Window | PositionFix


def float_rng(seed: int, float_id: str) -> np.random.Generator:
    """The float's generator: seeded from the config seed and the float id, so a float's
    result does not depend on which other floats are processed, or in which order."""
    return np.random.default_rng([seed, zlib.crc32(float_id.encode("utf-8"))])


def observations(windows: Sequence[Window], end_fix: PositionFix | None) -> list[Observation]:
    """The windows in time order, with the end fix after every window at or before its time."""
    events: list[Observation] = list(windows)
    if end_fix is not None:
        events.insert(int(np.searchsorted([w.time for w in windows], end_fix.time, side="right")), end_fix)
    return events


@dataclass(frozen=True)
class Step:
    """One filter step: a listening window or a position fix, and the weighted cloud after it."""

    cloud: Cloud
    loglik: float  # log p(y_t | y_1..t-1), the step's evidence
    ess: float
    observation: Observation
    beacon_index: NDArray[np.intp]  # beacon-table rows of the label_probs rows
    label_probs: NDArray[np.float64] | None  # (s, K) filtered P(signal j from beacon i), if kept

    @property
    def window(self) -> Window | None:
        return self.observation if isinstance(self.observation, Window) else None


@dataclass(frozen=True)
class FilterResult:
    """The filter's steps (when kept), and what it counted and met on the way."""

    steps: list[Step]
    n_steps: int
    n_resamples: int
    warnings: list[str]


@dataclass(frozen=True)
class FilterSettings:
    particles: int
    resample_ess_fraction: float
    resampler: Resampler


class ParticleFilter:
    """Bootstrap particle filter for one float (see module docstring)."""

    def __init__(
        self,
        motion: MotionModel,
        arrivals: ArrivalLikelihood,
        fixes: Likelihood,
        settings: FilterSettings,
        *,
        label_probs: bool = True,
    ):
        """`label_probs=False` skips the filtered association marginals (when only smoothed
        labels are wanted, which are recomputed after smoothing)."""
        self.motion = motion
        self.arrivals = arrivals
        self.fixes = fixes
        self.settings = settings
        self.label_probs = label_probs

    def run(
        self,
        launch: PositionFix,
        events: Sequence[Observation],
        rng: np.random.Generator,
        *,
        keep: bool = True,
        on_step: Callable[[Step], None] | None = None,
    ) -> FilterResult:
        """Filter `events` from the launch fix. Each step is passed to `on_step` as it is
        made; `keep=False` keeps none of them (memory then does not grow with the record)."""
        n = self.settings.particles
        particles = self.motion.initial(launch.lat, launch.lon, launch.sd_km, n, rng)
        log_w = np.zeros(n)
        t_prev = launch.time
        kept: list[Step] = []
        warnings: list[str] = []
        n_resamples = 0
        for obs in events:
            particles = self.motion.propagate(particles, days_between(t_prev, obs.time), rng)
            t_prev = obs.time
            evidence = self._evaluate(particles, obs)
            warnings.extend(evidence.warnings)
            loglik, skipped = _finite_loglik(evidence.loglik, obs, self.arrivals.info.float_id, warnings)
            _, log_prior = normalise_log_weights(log_w)
            log_w = log_w + loglik
            weights, log_post = normalise_log_weights(log_w)
            eff = ess(weights)
            probs = None
            if self.label_probs:
                p_match = evidence.p_match if evidence.p_match is not None else np.zeros((n, 0, 0))
                probs = np.einsum("p,psk->sk", weights, p_match)
            step = Step(
                cloud=Cloud(obs.time, particles, weights),
                loglik=np.nan if skipped else log_post - log_prior,
                ess=eff,
                observation=obs,
                beacon_index=evidence.beacon_index,
                label_probs=probs,
            )
            if on_step is not None:
                on_step(step)
            if keep:
                kept.append(step)
            if eff < self.settings.resample_ess_fraction * n:
                particles = particles.take(self.settings.resampler(weights, rng))
                log_w = np.zeros(n)
                n_resamples += 1
        return FilterResult(kept, len(events), n_resamples, warnings)

    def _evaluate(self, particles, obs: Observation) -> Evidence:
        if isinstance(obs, Window):
            return self.arrivals.evaluate(particles, obs, marginals=self.label_probs)
        return self.fixes.evaluate(particles, obs)


def _finite_loglik(loglik: NDArray, obs: Observation, float_id: str, warnings: list[str]) -> tuple[NDArray, bool]:
    """Guard against a non-finite likelihood (a bug or an extreme setting, not data: the
    ranked model always keeps an all-clutter explanation). Particles with one get zero
    weight; if none is finite the step is skipped (no update), with a warning either way.
    Returns the log-likelihood to use and whether the step was skipped."""
    bad = ~np.isfinite(loglik)
    if not bad.any():
        return loglik, False
    when = f"{float_id}: {np.datetime_as_string(obs.time, 's')}Z"
    if bad.all():
        warnings.append(f"{when}: likelihood not finite for any particle; this step was skipped")
        return np.zeros_like(loglik), True
    warnings.append(f"{when}: likelihood not finite for {int(bad.sum())} particle(s); they were dropped")
    return np.where(bad, -np.inf, loglik), False
