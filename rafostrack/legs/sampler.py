"""Metropolis-Hastings over leg trajectories (paper section 4.4), with our moves beside the paper's.

Target: pi(theta | y) ~ L(y | theta) pi(theta) (paper eq. 2), L a per-measurement
likelihood (`scores`, or a float's windows), pi the leg prior (`model`). Moves, each
chosen with its weight per iteration:

- `leg` (the paper's): change the speed, the heading or the duration of one or more
  legs (1-3, uniformly), later legs following (chained). Speed and heading: Gaussian
  random walks of variance 3 and 0.025 (paper: N(theta, 3), N(theta, .025)); duration:
  an independent draw from U(1, 40) (paper). Symmetric: accept with the ratio of
  pi_leg = prior x likelihood in leg coordinates.
- `knot` (ours): move one knot (a leg boundary's position) by a Gaussian step; only its
  two legs change, the rest of the trajectory stays. Ratio of pi_knot (model docstring).
- `shift` (ours): move one change time, knots fixed; ratio of pi_knot.
- `start` (ours, with a free start): translate the whole trajectory.
- `level` (ours, for a likelihood with `n_levels` > 1): move a discrete hyperparameter of
  the likelihood (e.g. how far a float wanders off its legs) to a neighbouring level,
  uniform prior over the levels; every term is recomputed.
- `jump` (ours: reversible jump over K, `rjmcmc`): split a leg at a uniform time with
  a Gaussian kink (sd: the knot step times `kink_scale`), or merge two neighbouring legs.

Step sizes of the knot, shift and start moves adapt during burn-in (towards 30%
acceptance), then stay fixed; the paper's proposals adapt only with `adapt`. Every draw comes from the given Generator.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from .model import LegPrior, Legs, log_jacobian, log_prior
from .rjmcmc import merge, split, split_probability
from .trajectory import positions

TARGET_ACCEPTANCE = 0.3


class PointLikelihood(Protocol):
    """Per-observation log-likelihood terms at fixed observation times (a likelihood with an
    attribute `n_levels` > 1 takes `level=` too: a discrete hyperparameter the sampler moves)."""

    @property
    def times(self) -> NDArray[np.float64]: ...

    def terms(self, xy: NDArray, index: slice) -> NDArray[np.float64]: ...


@dataclass(frozen=True)
class SamplerConfig:
    """Iterations, burn-in, move weights and step sizes (defaults: the paper's sampler)."""

    iterations: int = 5000
    burn_in_fraction: float = 0.25  # paper: a quarter of the iterations
    max_kept: int = 1000  # thin the kept samples to at most this many
    moves: dict[str, float] = field(default_factory=lambda: {"leg": 1.0})
    speed_step_var: float = 3.0  # paper
    heading_step_var: float = 0.025  # paper
    duration_proposal: tuple[float, float] = (1.0, 40.0)  # paper: U(1, 40)
    knot_step: float = 1.0  # length units; adapted during burn-in
    shift_step: float = 2.0  # time units; adapted
    start_step: float = 1.0  # adapted
    kink_scale: float = 1.0  # the split's Gaussian kink sd, as a multiple of the (adapted) knot step
    max_legs: int = 200
    adapt: bool = False  # adapt the leg moves' steps too (never in the paper's sampler)

    def __post_init__(self) -> None:
        unknown = set(self.moves) - {"leg", "knot", "shift", "start", "jump", "level"}
        if unknown or not self.moves or min(self.moves.values()) < 0:
            raise ValueError(f"bad move weights {self.moves}")


@dataclass(frozen=True)
class Chain:
    """The kept samples (after burn-in, thinned) and the run's statistics."""

    samples: tuple[Legs, ...]
    log_posterior: NDArray[np.float64]  # log pi_leg of each kept sample (up to a constant)
    n_legs_trace: NDArray[np.int64]  # K at every iteration
    levels: NDArray[np.int64]  # the likelihood's level at each kept sample (0 without levels)
    best: Legs  # the highest log pi_leg visited (MAP estimate)
    best_log_posterior: float
    acceptance: dict[str, float]
    steps: dict[str, float]  # the step sizes after adaptation
    seconds: float

    @property
    def n_legs(self) -> NDArray[np.int64]:
        return np.array([s.n_legs for s in self.samples])


@dataclass
class _State:
    legs: Legs
    terms: NDArray[np.float64]
    loglik: float
    logprior: float
    logjac: float
    level: int = 0

    def target(self, coords: str) -> float:
        return self.loglik + self.logprior + (self.logjac if coords == "knot" else 0.0)


# A proposal: new legs, log q(reverse) - log q(forward), coordinates of the ratio, and the
# time interval whose observations change.
Proposal = tuple[Legs, float, str, float, float]
Move = Callable[[Legs, np.random.Generator], Proposal | None]


TermsAt = Callable[[NDArray, slice, int], NDArray]  # (positions, observation slice, level) -> log-lik terms


@dataclass
class _Record:
    """What the chain keeps: K at every iteration, the thinned samples after burn-in with
    their log pi_leg and level, and the best state visited."""

    trace: NDArray[np.int64]
    best: Legs
    best_lp: float
    kept: list[Legs] = field(default_factory=list)
    kept_lp: list[float] = field(default_factory=list)
    kept_level: list[int] = field(default_factory=list)

    def note_best(self, state: _State) -> None:
        if state.target("leg") > self.best_lp:
            self.best, self.best_lp = state.legs, state.target("leg")

    def keep(self, state: _State) -> None:
        self.kept.append(state.legs)
        self.kept_lp.append(state.target("leg"))
        self.kept_level.append(state.level)


def run_chain(
    likelihood: PointLikelihood,
    prior: LegPrior,
    start: Legs,
    config: SamplerConfig,
    rng: np.random.Generator,
    *,
    free_start: bool = True,
) -> Chain:
    """Run the sampler from `start` (module docstring)."""
    started = time.perf_counter()
    times = likelihood.times
    n_levels = int(getattr(likelihood, "n_levels", 1))
    terms_at = _terms_function(likelihood, n_levels)
    state = _start_state(likelihood, prior, start, config, terms_at)
    steps = {
        "speed": math.sqrt(config.speed_step_var),
        "heading": math.sqrt(config.heading_step_var),
        "knot": config.knot_step,
        "shift": config.shift_step,
        "start": config.start_step,
    }
    adaptive = {"knot", "shift", "start"} | ({"speed", "heading"} if config.adapt else set())
    names, weights = _move_weights(config, free_start, n_levels)
    tried = dict.fromkeys(names, 0)
    accepted = dict.fromkeys(names, 0)
    burn = int(config.burn_in_fraction * config.iterations)
    thin = max(1, math.ceil((config.iterations - burn) / config.max_kept))
    record = _Record(np.empty(config.iterations, dtype=np.int64), state.legs, state.target("leg"))
    choices = rng.choice(len(names), size=config.iterations, p=weights)
    for it in range(config.iterations):
        name = names[choices[it]]
        if name == "level":
            state, ok = _level_move(state, n_levels, terms_at, times, rng)
            step_key = "level"
        else:
            proposal, step_key = _propose(name, state.legs, rng, steps, config, prior, free_start)
            ok = False
            if proposal is not None:
                state, ok = _metropolis_hastings(state, proposal, prior, times, terms_at, rng)
                if ok:
                    record.note_best(state)
        tried[name] += 1
        accepted[name] += ok
        if it < burn and step_key in adaptive:
            steps[step_key] *= math.exp((float(ok) - TARGET_ACCEPTANCE) / math.sqrt(1.0 + tried[name] / 10.0))
        record.trace[it] = state.legs.n_legs
        if it >= burn and (it - burn) % thin == 0:
            record.keep(state)
    return Chain(
        samples=tuple(record.kept),
        log_posterior=np.array(record.kept_lp),
        n_legs_trace=record.trace,
        levels=np.array(record.kept_level, dtype=np.int64),
        best=record.best,
        best_log_posterior=record.best_lp,
        acceptance={m: accepted[m] / max(tried[m], 1) for m in names},
        steps=steps,
        seconds=time.perf_counter() - started,
    )


def _terms_function(likelihood: PointLikelihood, n_levels: int) -> TermsAt:
    """The likelihood's terms at a level (the level ignored by a likelihood without levels)."""

    def terms_at(xy: NDArray, index: slice, at: int) -> NDArray[np.float64]:
        return likelihood.terms(xy, index, level=at) if n_levels > 1 else likelihood.terms(xy, index)  # type: ignore[call-arg]

    return terms_at


def _start_state(
    likelihood: PointLikelihood, prior: LegPrior, start: Legs, config: SamplerConfig, terms_at: TermsAt
) -> _State:
    """The chain's first state: `start` (repaired for the knot moves: leg coordinates have
    no 1/|d| pole) at the likelihood's starting level; ValueError if its density is zero."""
    times = likelihood.times
    knot_moves = any(config.moves.get(m, 0) > 0 for m in ("knot", "shift", "jump"))
    legs = repair_start(start, prior) if knot_moves else start
    level = int(getattr(likelihood, "start_level", 0))
    terms = terms_at(positions(legs, times), slice(0, len(times)), level)
    state = _State(legs, terms, float(terms.sum()), log_prior(legs, prior), log_jacobian(legs), level)
    if not math.isfinite(state.logprior + state.loglik):
        raise ValueError("the starting trajectory has zero posterior density")
    return state


def _move_weights(config: SamplerConfig, free_start: bool, n_levels: int) -> tuple[list[str], NDArray[np.float64]]:
    """The moves in use (`start` only with a free start, `level` only with levels) and
    their normalised weights."""
    names = [
        m
        for m, w in config.moves.items()
        if w > 0 and not (m == "start" and not free_start) and not (m == "level" and n_levels < 2)
    ]
    weights = np.array([config.moves[m] for m in names], dtype=float)
    weights /= weights.sum()
    return names, weights


def _metropolis_hastings(
    state: _State, proposal: Proposal, prior: LegPrior, times: NDArray, terms_at: TermsAt, rng: np.random.Generator
) -> tuple[_State, bool]:
    """Accept `proposal` with probability min(1, pi(new) q(back) / pi(old) q(forward)), pi in
    the proposal's coordinates; only the terms of observations in its interval are
    recomputed. The new or unchanged state, and whether it was accepted."""
    new, log_q, coords, a, b = proposal
    lp = log_prior(new, prior)
    if not lp > -math.inf:  # zero prior density (or NaN)
        return state, False
    lo, hi = np.searchsorted(times, a, "left"), np.searchsorted(times, b, "right")
    new_terms = terms_at(positions(new, times[lo:hi]), slice(lo, hi), state.level)
    loglik = state.loglik - float(state.terms[lo:hi].sum()) + float(new_terms.sum())
    cand = _State(new, state.terms, loglik, lp, log_jacobian(new) if coords == "knot" else 0.0, state.level)
    if coords == "knot":
        log_ratio = cand.target("knot") - state.target("knot") + log_q
    else:
        log_ratio = cand.target("leg") - state.target("leg") + log_q
    if not (math.isfinite(log_ratio) and math.log(rng.random()) < log_ratio):
        return state, False
    terms = state.terms.copy()
    terms[lo:hi] = new_terms
    return _State(new, terms, float(terms.sum()), lp, log_jacobian(new), state.level), True


def _level_move(
    state: _State, n_levels: int, terms_at: TermsAt, times: NDArray,
    rng: np.random.Generator,
) -> tuple[_State, bool]:  # fmt: skip
    """Move the likelihood's level to a neighbour (uniform among the 1 or 2 there are);
    uniform prior, Hastings ratio = neighbours(l) / neighbours(l')."""
    lv = state.level
    options = [x for x in (lv - 1, lv + 1) if 0 <= x < n_levels]
    new = options[int(rng.integers(len(options)))]
    back = sum(1 for x in (new - 1, new + 1) if 0 <= x < n_levels)
    terms = terms_at(positions(state.legs, times), slice(0, len(times)), new)
    loglik = float(terms.sum())
    log_ratio = loglik - state.loglik + math.log(len(options) / back)
    if math.isfinite(log_ratio) and math.log(rng.random()) < log_ratio:
        return _State(state.legs, terms, loglik, state.logprior, state.logjac, new), True
    return state, False


REPAIR_FRACTION = 1e-3


def repair_start(legs: Legs, prior: LegPrior) -> Legs:
    """`legs` with any zero-length leg (a start on the knot density's 1/|d| pole) given a
    tiny displacement, REPAIR_FRACTION of the prior's mean speed times its duration, along
    the previous heading; the trajectory barely moves."""
    d = legs.displacements.copy()
    length = legs.lengths
    if np.all(length > 0):
        return legs
    heading = 0.0
    for i in range(len(d)):
        if length[i] > 0:
            heading = math.atan2(d[i, 1], d[i, 0])
        else:
            speed = REPAIR_FRACTION * max(prior.speed_mean, prior.speed_sd)
            d[i] = speed * legs.durations[i] * np.array([math.cos(heading), math.sin(heading)])
    knots = legs.knots[0] + np.vstack([[0.0, 0.0], np.cumsum(d, axis=0)])
    return Legs(legs.cuts.copy(), knots)


def _propose(
    name: str, legs: Legs, rng: np.random.Generator, steps: dict[str, float], config: SamplerConfig,
    prior: LegPrior, free_start: bool,
) -> tuple[Proposal | None, str]:  # fmt: skip
    if name == "leg":
        return _leg_move(legs, rng, steps, config)
    if name == "knot":
        return _knot_move(legs, rng, steps["knot"], free_start), "knot"
    if name == "shift":
        return _shift_move(legs, rng, steps["shift"]), "shift"
    if name == "start":
        delta = rng.normal(0.0, steps["start"], 2)
        return (Legs(legs.cuts, legs.knots + delta), 0.0, "leg", -math.inf, math.inf), "start"
    kink = steps["knot"] * config.kink_scale  # fixed after burn-in, like the knot step
    if rng.random() < split_probability(legs.n_legs, config.max_legs):
        return split(legs, rng, kink, config.max_legs), "jump"
    return merge(legs, rng, kink, config.max_legs), "jump"


def _leg_move(
    legs: Legs, rng: np.random.Generator, steps: dict[str, float], config: SamplerConfig
) -> tuple[Proposal | None, str]:
    """The paper's move (module docstring): speed, heading or duration of 1-3 legs."""
    k = legs.n_legs
    kinds = ("speed", "heading", "duration") if k > 1 else ("speed", "heading")
    kind = kinds[rng.integers(len(kinds))]
    pool = k - 1 if kind == "duration" else k
    m = int(rng.integers(1, min(3, pool) + 1))
    which = rng.choice(pool, size=m, replace=False)
    speeds, headings, durations = legs.speeds, legs.headings, legs.durations[:-1].copy()
    if kind == "speed":
        speeds = speeds.copy()
        speeds[which] += rng.normal(0.0, steps["speed"], m)
        if np.any(speeds < 0):
            return None, "speed"
    elif kind == "heading":
        headings = headings.copy()
        headings[which] += rng.normal(0.0, steps["heading"], m)
    else:
        lo, hi = config.duration_proposal
        durations[which] = rng.uniform(lo, hi, m)
        if legs.cuts[0] + durations.sum() >= legs.cuts[-1]:
            return None, "duration"
    if kind == "duration" and np.any(durations < 0):
        return None, kind
    new = Legs.from_parameters(legs.knots[0], legs.cuts[0], legs.cuts[-1], speeds, headings, durations)
    first = int(which.min())
    a = -math.inf if first == 0 else float(legs.cuts[first])  # times before the start follow leg 0
    return (new, 0.0, "leg", a, math.inf), kind


def _knot_move(legs: Legs, rng: np.random.Generator, step: float, free_start: bool) -> Proposal:
    k = legs.n_legs
    j = int(rng.integers(0 if free_start else 1, k + 1))
    knots = legs.knots.copy()
    knots[j] += rng.normal(0.0, step, 2)
    a = -math.inf if j == 0 else float(legs.cuts[j - 1])
    b = math.inf if j == k else float(legs.cuts[j + 1])
    return Legs(legs.cuts, knots), 0.0, "knot", a, b


def _shift_move(legs: Legs, rng: np.random.Generator, step: float) -> Proposal | None:
    k = legs.n_legs
    if k < 2:
        return None
    j = int(rng.integers(1, k))
    c = legs.cuts[j] + rng.normal(0.0, step)
    if not (legs.cuts[j - 1] < c < legs.cuts[j + 1]):
        return None
    cuts = legs.cuts.copy()
    cuts[j] = c
    return Legs(cuts, legs.knots), 0.0, "knot", float(legs.cuts[j - 1]), float(legs.cuts[j + 1])
