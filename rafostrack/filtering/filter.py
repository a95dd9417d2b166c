"""The particle filter over float position with per-window evidence (paper Alg. 1).

For each observation in time order: move the particles with the motion model over the
interval since the previous one (one exact transition, however long the gap), weight
each by the observation's likelihood (a window's arrival times, or a position fix), keep
the weighted cloud and the association marginals averaged over it, then resample when
the effective sample size drops below the threshold, each mode of the cloud on its own
(`FilterSettings.resample`, `rafostrack.filtering.modes`). The launch fix is the prior. Weights
stay in log space throughout.

The filter is assembled from components (`rafostrack.motion`, `rafostrack.likelihoods`,
`rafostrack.filtering.resampling`) and knows nothing else about them; its counts and warnings come
back in a `FilterResult`.
"""

from __future__ import annotations

import zlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from ..config import FilterConfig
from ..domain import Cloud, Particles, PositionFix, Window, days_between
from ..errors import Notice, WarningKind
from ..likelihoods import ArrivalLikelihood, Evidence, Likelihood, MoveFactor
from ..motion import MotionModel
from .guided import Guide
from .modes import mode_labels
from .recovery import RecoveryMonitor, RecoverySettings
from .resampling import RESAMPLERS, Resampler, ess, normalise_log_weights, resample_within, within_mode_ess

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
    reseeded_mass: float = 0.0  # posterior mass of particles re-seeded by the recovery search

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
    n_checks: int = 0  # windows the recovery monitor searched
    n_reseeds: int = 0  # windows where it re-seeded part of the cloud
    prior: Cloud | None = None  # the particles drawn about the starting fix, equally weighted


@dataclass(frozen=True)
class Resampled:
    """The cloud after the resampling stage: particles, their log weights, and whether the
    within-mode ESS triggered a resampling (else the particles are the inputs, unchanged)."""

    particles: Particles
    log_weights: NDArray[np.float64]
    resampled: bool


@dataclass(frozen=True)
class FilterSettings:
    """Size and resampling of the cloud; modes as in `rafostrack.filtering.modes`."""

    particles: int
    resample_ess_fraction: float
    resampler: Resampler
    mode_link_km: float
    max_modes: int
    min_mode_mass: float

    @classmethod
    def from_config(cls, config: FilterConfig) -> FilterSettings:
        """`[filter]`'s settings of the cloud (their defaults in default.toml)."""
        return cls(
            config.particles,
            config.resample_ess_fraction,
            RESAMPLERS[config.resampling],
            config.mode_link_km,
            config.max_modes,
            config.min_mode_mass,
        )

    def resample(self, particles: Particles, weights: NDArray, rng: np.random.Generator) -> Resampled:
        """Resample within modes when their summed ESS is below `resample_ess_fraction` x N:
        the new particles and their log weights, or the inputs unchanged (log weights)."""
        labels = mode_labels(particles.lat, particles.lon, weights, self.mode_link_km)
        if within_mode_ess(weights, labels) >= self.resample_ess_fraction * len(weights):
            with np.errstate(divide="ignore"):  # a particle dropped as non-finite has weight 0
                return Resampled(particles, np.log(weights), resampled=False)
        ancestors, new_weights = resample_within(
            weights,
            labels,
            self.resampler,
            rng,
            min_count=max(1, self.particles // (2 * self.max_modes)),
            min_mass=self.min_mode_mass,
            max_modes=self.max_modes,
        )
        return Resampled(particles.take(ancestors), np.log(new_weights), resampled=True)


class Proposal(Protocol):
    """A data-driven proposal q(x' | x) for new particle states, one per ancestor x
    (`recovery.Reseeding`, which ignores the ancestor; `guided.GuidedDrift`)."""

    def sample(self, ancestors: Particles, rng: np.random.Generator) -> Particles: ...

    def log_density(self, ancestors: Particles, particles: Particles) -> NDArray[np.float64]: ...


@dataclass(frozen=True)
class _Proposed:
    """A step's new particle states (the motion model's draws, part of them redrawn from the
    data-driven proposals) and their evidence."""

    moved: Particles
    evidence: Evidence
    source: NDArray[np.intp]  # which draw each particle came from: 0 the motion model, k proposal k
    correction: NDArray[np.float64]  # log f(x' | x) - log of the mixture's density (0 without proposals)
    reseed_source: int = -1  # the `source` value of re-seeded particles, -1 when none


class ParticleFilter:
    """Particle filter for one float (see module docstring), with an optional data-driven
    proposal: a recovery monitor that re-seeds a lost cloud."""

    def __init__(
        self,
        motion: MotionModel,
        arrivals: ArrivalLikelihood,
        fixes: Likelihood,
        settings: FilterSettings,
        *,
        label_probs: bool = True,
        recovery: RecoverySettings | None = None,
        factors: Sequence[MoveFactor] = (),
        guide: Guide | None = None,
    ):
        """`factors` weigh each particle's move (e.g. context constraints). `guide` draws
        part of the cloud from a proposal guided by each window (`rafostrack.filtering.guided`).
        `label_probs=False` skips the filtered association marginals (when only smoothed
        labels are wanted, which are recomputed after smoothing)."""
        self.motion = motion
        self.arrivals = arrivals
        self.fixes = fixes
        self.settings = settings
        self.label_probs = label_probs
        self.recovery = recovery
        self.factors = tuple(factors)
        self.guide = guide

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
        made; `keep=False` keeps none of them (memory then does not grow with the record).
        A step: propagate -> propose -> reweight -> summarise (`_step`), then resample."""
        n = self.settings.particles
        particles = self.motion.initial(launch.lat, launch.lon, launch.sd_km, n, rng)
        log_w = np.zeros(n)
        prior = Cloud(launch.time, particles, np.full(n, 1.0 / n))
        monitor = None if self.recovery is None else RecoveryMonitor(self.recovery, self.arrivals, self.motion)
        t_prev = launch.time
        kept: list[Step] = []
        warnings: list[str] = []
        n_resamples = 0
        for obs in events:
            dt_days = abs(days_between(t_prev, obs.time))  # a backward run goes back in time
            step = self._step(particles, log_w, obs, dt_days, monitor, warnings, rng)
            t_prev = obs.time
            if on_step is not None:
                on_step(step)
            if keep:
                kept.append(step)
            after = self.settings.resample(step.cloud.particles, step.cloud.weights, rng)
            particles, log_w = after.particles, after.log_weights
            n_resamples += after.resampled
        checks = (monitor.n_checks, monitor.n_reseeds) if monitor is not None else (0, 0)
        return FilterResult(kept, len(events), n_resamples, warnings, *checks, prior=prior)

    def _step(
        self,
        particles: Particles,
        log_w: NDArray[np.float64],
        obs: Observation,
        dt_days: float,
        monitor: RecoveryMonitor | None,
        warnings: list[str],
        rng: np.random.Generator,
    ) -> Step:
        """One step up to resampling: move the particles by the motion model, redraw part of
        them from the data-driven proposals, reweight, and summarise the weighted cloud.
        The step's evidence is log sum(w_post) - log sum(w_prior)."""
        prior_weights, log_prior = normalise_log_weights(log_w)
        moved = self.motion.propagate(particles, dt_days, rng)
        proposed = self._propose(particles, moved, obs, dt_days, prior_weights, monitor, rng)
        warnings.extend(proposed.evidence.warnings)
        log_w, skipped = self._reweight(particles, log_w, proposed, obs, warnings)
        weights, log_post = normalise_log_weights(log_w)
        if monitor is not None and isinstance(obs, Window):
            monitor.record(log_post - log_prior)
        return self._summarise(obs, proposed, weights, np.nan if skipped else log_post - log_prior)

    def _propose(
        self,
        particles: Particles,
        moved: Particles,
        obs: Observation,
        dt_days: float,
        prior_weights: NDArray[np.float64],
        monitor: RecoveryMonitor | None,
        rng: np.random.Generator,
    ) -> _Proposed:
        """The motion model's draws `moved` and their evidence, with part of them redrawn from
        the proposals this observation calls for (`_proposals`, `_mix`)."""
        n = self.settings.particles
        evidence = self._evaluate(moved, obs)
        proposals, reseed_source = self._proposals(obs, dt_days, moved, prior_weights, evidence.loglik, monitor)
        if not proposals:
            return _Proposed(moved, evidence, np.zeros(n, dtype=np.intp), np.zeros(n), reseed_source)
        moved, evidence, source, correction = self._mix(particles, moved, evidence, obs, dt_days, proposals, rng)
        return _Proposed(moved, evidence, source, correction, reseed_source)

    def _proposals(
        self,
        obs: Observation,
        dt_days: float,
        moved: Particles,
        prior_weights: NDArray[np.float64],
        loglik: NDArray[np.float64],
        monitor: RecoveryMonitor | None,
    ) -> tuple[list[tuple[float, Proposal]], int]:
        """The data-driven proposals for a window with their shares alpha_k: the recovery
        search's re-seeding (when the monitor finds the cloud lost), then the guided drift on
        a share of the particles the re-seeding leaves; and the re-seeding's `source` value
        (its position in the list, from 1; -1 when none)."""
        proposals: list[tuple[float, Proposal]] = []
        reseed_source = -1
        if not isinstance(obs, Window):
            return proposals, reseed_source
        if monitor is not None:
            reseed = monitor.proposal(obs, dt_days, moved, prior_weights, loglik)
            if reseed is not None:
                proposals.append((monitor.settings.fraction, reseed))
                reseed_source = len(proposals)
        if self.guide is not None:
            guided = self.guide.proposal(self.motion, dt_days, moved, prior_weights, loglik)
            if guided is not None:
                proposals.append((self.guide.fraction * (1.0 - sum(a for a, _ in proposals)), guided))
        return proposals, reseed_source

    def _reweight(
        self,
        particles: Particles,
        log_w: NDArray[np.float64],
        proposed: _Proposed,
        obs: Observation,
        warnings: list[str],
    ) -> tuple[NDArray[np.float64], bool]:
        """log w' = log w + log p(y | x') + the proposal correction + sum over move factors of
        log g(x, x'); and whether the step was skipped (no particle with a finite likelihood)."""
        loglik, skipped = _finite_loglik(proposed.evidence.loglik, obs, self.arrivals.info.float_id, warnings)
        log_w = log_w + loglik + proposed.correction
        for factor in self.factors:
            log_w = log_w + factor.log_weight(particles, proposed.moved, obs)
        return log_w, skipped

    def _summarise(self, obs: Observation, proposed: _Proposed, weights: NDArray[np.float64], loglik: float) -> Step:
        """The step's weighted cloud, ESS, evidence and (if kept) association marginals
        P(signal j from beacon i) = sum_p W_p P_p(j from i)."""
        probs = None
        if self.label_probs:
            p_match = proposed.evidence.p_match
            if p_match is None:
                p_match = np.zeros((self.settings.particles, 0, 0))
            probs = np.einsum("p,psk->sk", weights, p_match)
        return Step(
            cloud=Cloud(obs.time, proposed.moved, weights),
            loglik=loglik,
            ess=ess(weights),
            observation=obs,
            beacon_index=proposed.evidence.beacon_index,
            label_probs=probs,
            reseeded_mass=float(weights[proposed.source == proposed.reseed_source].sum()),
        )

    def _evaluate(self, particles: Particles, obs: Observation) -> Evidence:
        if isinstance(obs, Window):
            return self.arrivals.evaluate(particles, obs, marginals=self.label_probs)
        return self.fixes.evaluate(particles, obs)

    def _mix(
        self,
        before: Particles,
        moved: Particles,
        evidence: Evidence,
        obs: Observation,
        dt_days: float,
        proposals: list[tuple[float, Proposal]],
        rng: np.random.Generator,
    ) -> tuple[Particles, Evidence, NDArray[np.intp], NDArray[np.float64]]:
        """Draw each particle's new state from the motion model (already in `moved`) or, with
        probability alpha_k, from proposal k given its ancestor; return the states, their
        evidence, which proposal each came from (0 = motion) and the log weight correction
        log f(x' | x) - log [alpha_0 f(x' | x) + sum_k alpha_k q_k(x' | x)]
        (multiple importance sampling, balance heuristic: every draw is weighted by the
        mixture it may have come from). A proposal redraws the position (and velocity); the
        part of the state it carries over from the motion's draw (`MotionModel.
        log_carried_transition`, the float clock) has the motion's density under it too."""
        n = len(moved)
        alphas = np.array([1.0 - sum(a for a, _ in proposals)] + [a for a, _ in proposals])
        source = rng.choice(len(alphas), size=n, p=alphas)
        for k, (_, proposal) in enumerate(proposals, start=1):
            slots = np.flatnonzero(source == k)
            if len(slots):
                moved = moved.replace_at(slots, proposal.sample(before.take(slots), rng))
        redrawn = np.flatnonzero(source > 0)
        if len(redrawn):
            evidence = _merge_evidence(evidence, redrawn, self._evaluate(moved.take(redrawn), obs))
        log_f = self.motion.log_transition(before, moved, dt_days)
        carried = self.motion.log_carried_transition(before, moved, dt_days)  # a proposal's draw carries it over
        terms = [np.log(alphas[0]) + log_f]
        terms += [np.log(a) + q.log_density(before, moved) + carried for a, q in proposals]
        return moved, evidence, source, log_f - np.logaddexp.reduce(np.array(terms), axis=0)


def _merge_evidence(base: Evidence, index: NDArray[np.intp], other: Evidence) -> Evidence:
    """`base` with the particles at `index` replaced by `other`'s (same observation)."""
    loglik = base.loglik.copy()
    loglik[index] = other.loglik
    p_match = None
    if base.p_match is not None and other.p_match is not None:
        p_match = base.p_match.copy()
        p_match[index] = other.p_match
    return Evidence(loglik, base.beacon_index, p_match, base.warnings + other.warnings)


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
        warnings.append(
            Notice(WarningKind.LIKELIHOOD, f"{when}: likelihood not finite for any particle; this step was skipped")
        )
        return np.zeros_like(loglik), True
    dropped = f"{when}: likelihood not finite for {int(bad.sum())} particle(s); they were dropped"
    warnings.append(Notice(WarningKind.LIKELIHOOD, dropped))
    return np.where(bad, -np.inf, loglik), False
