"""The mission's array fit: every float's confident arrivals in one problem whose shared
block is the sound-source array (each source's offset, drift, sound-speed deviation and
position, and the shared sound speed), fitted by Gauss-Newton on the block-arrow normal
equations (`schur`).

Each float keeps its own nodes, clock and mean current, and its own hyperparameters (fitted
to its arrivals once, at the first linearisation, by maximum marginal likelihood as its
own calibration does); its arrivals' weights are refitted at every step (`MultipathEM`: a
delayed or mislabelled arrival gets little weight), and are 0 for a source whose arrivals
the float has set aside (`MissionFloat.set_aside`). The array's unknowns theta are
corrections to the tables as given, under the priors of `KalmanPriors` put in once for the
mission (a float's normal equations leave them out: `linearise(..., array_priors=False)`);
a source whose value the mission contradicts is `released` (wide priors) and fitted again,
so that its estimate is the arrivals'.

Layout of theta: the shared slowness deviation, then per source (`ArrayLayout.sources`,
beacon-table rows) its five unknowns in `SOURCE_BLOCKS` order.

Each step's per-float work (a float's linearisation, its block of the normal equations and
its arrivals' weights refitted) is independent of every other float's: `float_step` over a
`FloatTask`, mapped by `map_floats` (in order; `rafostrack batch` maps it over its worker
processes, with the same results as the builtin `map`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..calibrate import kalman
from ..calibrate.kalman_problem import NODE
from ..calibrate.noise import MultipathEM, fit_multipath_em
from ..config import Config
from .floats import BANDWIDTH, MissionFloat, referred
from .schur import FloatBlock, outlying_together, solve_mission

# A source's unknowns, in the order of `kalman_problem.Problem.per_beacon`'s blocks.
SOURCE_BLOCKS = ("offset_s", "drift_s_per_day", "slowness_s_per_m", "east_km", "north_km")
ITERATIONS = 6
GATE_S = 60.0  # an arrival's residual beyond this: weight 0 (`_refitted_noise`)
# The arrivals' multipath refitted at each step by EM from the previous step's
# (`noise.fit_multipath_em`, which reads the first entry: 0.003 in logit eps and log tau):
# weights one Gauss-Newton step behind need no more, and a few EM steps from near the
# maximum take a quarter of Nelder-Mead's time at its 0.01 (which stops as near).
MULTIPATH_TOLERANCE = (3e-3, 1e-2)
SIGMA_CAP = 3.0  # a float's TOA sd at most this many times the configured one
# The most a Gauss-Newton step moves a source's unknown, per `SOURCE_BLOCKS` (None: free).
STEP_LIMITS = (20.0, 0.02, None, 20.0, 20.0)
OUTLIER_BLOCKS = (0, 1, 3, 4)  # a source's unknowns in which a float is tested for an outlier


@dataclass(frozen=True)
class ArrayLayout:
    """Where each source's unknowns are in theta, and each source's drift reference."""

    sources: NDArray[np.intp]  # (G,) beacon-table rows
    mid_days: NDArray[np.float64]  # (G,) mean days since the source's epoch of its arrivals

    @classmethod
    def of(cls, floats: Sequence[MissionFloat]) -> ArrayLayout:
        rows = np.concatenate([f.heard[f.problem.beacon] for f in floats])
        days = np.concatenate([f.days for f in floats])
        sources, index = np.unique(rows, return_inverse=True)
        mid = np.bincount(index, weights=days) / np.bincount(index)
        return cls(sources, mid)

    @property
    def size(self) -> int:
        return 1 + len(SOURCE_BLOCKS) * len(self.sources)

    def column(self, block: NDArray | int, source: NDArray | int) -> NDArray[np.intp]:
        """theta's index of `block`s (of `SOURCE_BLOCKS`) of sources (positions in `sources`)."""
        return np.asarray(1 + len(SOURCE_BLOCKS) * np.asarray(source) + block, dtype=np.intp)

    def arrival_sources(self, f: MissionFloat) -> NDArray[np.intp]:
        """(J,) each of a float's arrivals' source, as its position in `sources`."""
        return np.searchsorted(self.sources, f.heard)[f.problem.beacon]

    def float_columns(self, f: MissionFloat) -> NDArray[np.intp]:
        """theta's index of each of a float's array unknowns, in its problem's order."""
        where = np.searchsorted(self.sources, f.heard)
        return np.concatenate([[0], *(self.column(b, where) for b in range(len(SOURCE_BLOCKS)))]).astype(np.intp)


@dataclass(frozen=True)
class ArrayPriors:
    """The array's prior sds (theta's units), per source where released."""

    slowness_s_per_m: float
    source: NDArray[np.float64]  # (G, 5) per source and block

    @classmethod
    def of(
        cls, layout: ArrayLayout, priors: kalman.KalmanPriors, s0: float, released: NDArray[np.bool_] | None = None
    ) -> ArrayPriors:
        """`KalmanPriors`' sds; `released` (G, 5): the blocks under the released sds."""
        normal = [priors.offset_s, priors.drift_s_per_day, priors.beacon_sound_speed_m_s * s0 * s0,
                  priors.source_position_km, priors.source_position_km]  # fmt: skip
        wide = [priors.released_offset_s, priors.released_drift_s_per_day, priors.beacon_sound_speed_m_s * s0 * s0,
                priors.released_position_km, priors.released_position_km]  # fmt: skip
        free = np.zeros((len(layout.sources), 5), dtype=bool) if released is None else released
        return cls(priors.sound_speed_m_s * s0 * s0, np.where(free, np.array(wide), np.array(normal)))

    def sd(self) -> NDArray[np.float64]:
        """(theta size,) the prior sd of each unknown."""
        return np.concatenate([[self.slowness_s_per_m], self.source.ravel()])


@dataclass(frozen=True)
class ArrayFit:
    """The array fitted on the mission: theta, its covariance and the floats' jackknife
    spread of it, each float's own unknowns, arrival weights and residuals, the floats
    (with their fitted TOA sds)."""

    layout: ArrayLayout
    floats: list[MissionFloat]
    theta: NDArray[np.float64]
    covariance: NDArray[np.float64]
    jackknife: NDArray[np.float64]  # the floats' spread (`ArraySolution.jackknife_covariance`)
    own: list[NDArray[np.float64]]  # per float, its own unknowns
    weight: list[NDArray[np.float64]]  # per float, its arrivals' direct-path weights
    toa_residual_s: list[NDArray[np.float64]]
    priors: ArrayPriors
    s0: float  # the configured slowness (s/m)
    # (float, source) positions: an outlier among the floats hearing the source (`outlying_pairs`)
    outlying: list[tuple[int, int]] = dataclasses.field(default_factory=list)
    # per float, its block at the fit (the last step's), from which a fit started here
    # begins (`_restarted`); empty once the fit is judged (`MissionArray`)
    blocks: list[FloatBlock] = dataclasses.field(default_factory=list, repr=False)

    def correction(self, block: int) -> NDArray[np.float64]:
        """(G,) each source's fitted correction of `block`."""
        return self.theta[self.layout.column(block, np.arange(len(self.layout.sources)))]

    def unknowns(self, k: int) -> NDArray[np.float64]:
        """Float k's unknowns in its problem's order: its own, then its view of theta."""
        return np.concatenate([self.own[k], self.theta[self.layout.float_columns(self.floats[k])]])


@dataclass(frozen=True)
class FloatTask:
    """One float's work in a Gauss-Newton step: its unknowns u (own, then the array's
    columns), its arrivals' weights, and, unless this is the last step, how to refit them."""

    float_: MissionFloat
    unknowns: NDArray[np.float64]
    weight: NDArray[np.float64]
    columns: NDArray[np.intp]
    priors: kalman.KalmanPriors
    noise: MultipathEM
    sigma_cap_s: float
    refit: bool


@dataclass(frozen=True)
class FloatStep:
    """What a float's task gives: its block of the normal equations, its arrivals' residuals,
    and, refitted from those residuals, its hyperparameters (its TOA sd), its weights and its
    noise (not the float itself: its problem would cross between processes twice a step)."""

    block: FloatBlock
    residual_s: NDArray[np.float64]
    hyper: kalman.Hyper
    weight: NDArray[np.float64]
    noise: MultipathEM


# How the floats' work is mapped, in order: builtin map, or over worker processes (`float_step`, `refit`).
FloatMap = Callable[[Callable[[Any], Any], Iterable[Any]], Iterable[Any]]


def float_step(task: FloatTask) -> FloatStep:
    """A float's block of the normal equations at its unknowns, its arrivals' residuals
    there, and (`task.refit`) its weights and TOA sd refitted to them (`_refitted_noise`)."""
    f = task.float_
    lin = kalman.linearise(f.problem, task.unknowns, task.weight, task.priors, array_priors=False)
    normal = lin.normal(f.hyper)
    block = FloatBlock.of(normal.jtj, -normal.jtr, NODE * f.problem.n_nodes, BANDWIDTH, f.n_own, task.columns)
    if not task.refit:
        return FloatStep(block, lin.toa_residual_s, f.hyper, task.weight, task.noise)
    hyper, weight = _refitted_noise(f.hyper, lin.toa_residual_s, task.noise, task.sigma_cap_s)
    return FloatStep(block, lin.toa_residual_s, hyper, weight, task.noise)


def refit(task: tuple[kalman.Hyper, NDArray, MultipathEM, float]) -> tuple[kalman.Hyper, NDArray, MultipathEM]:
    """A float's hyperparameters and weights refitted to its residuals (`_refitted_noise`),
    and its noise: `float_step`'s refit alone."""
    hyper, residual_s, noise, sigma_cap_s = task
    refitted, weight = _refitted_noise(hyper, residual_s, noise, sigma_cap_s)
    return refitted, weight, noise


def _restarted(start: ArrayFit, noise: list[MultipathEM], sigma_cap_s: float, map_floats: FloatMap) -> list[FloatStep]:
    """The first step of a fit from `start`: the floats, unknowns and weights of its last
    step, so its blocks and residuals (`ArrayFit.blocks`); only the refit is done again."""
    tasks = [(f.hyper, r, em, sigma_cap_s) for f, r, em in zip(start.floats, start.toa_residual_s, noise, strict=True)]
    refitted = map_floats(refit, tasks)
    return [FloatStep(b, r, *fitted) for b, r, fitted in zip(start.blocks, start.toa_residual_s, refitted, strict=True)]


def _step_scale(d_theta: NDArray, layout: ArrayLayout) -> float:
    """The fraction of a Gauss-Newton step to take: the whole step unless a source's move
    exceeds `STEP_LIMITS` in one of its unknowns (a trust region: far from the solution the
    linearised model's step can overshoot by far, e.g. from floats whose labels are wrong),
    then the step shortened along its direction to that limit."""
    scale = 1.0
    for block, limit in enumerate(STEP_LIMITS):
        if limit is None:
            continue
        largest = float(np.max(np.abs(d_theta[layout.column(block, np.arange(len(layout.sources)))]), initial=0.0))
        if largest > limit:
            scale = min(scale, limit / largest)
    return scale


def _refitted_noise(
    hyper: kalman.Hyper, residual_s: NDArray, noise: MultipathEM, sigma_cap_s: float
) -> tuple[kalman.Hyper, NDArray]:
    """A float's arrivals' direct-path weights (multipath by EM; none beyond `GATE_S`:
    an arrival so far off is not the labelled source's, or the float's track is not where
    the float was) and its TOA sd from the weighted residuals, sigma^2 = sum w r^2 / sum w,
    at most `sigma_cap_s` (a float whose weighted residuals are wider does not fit the
    array: `MissionArray.floats_fitting`)."""
    weight = np.where(np.abs(residual_s) <= GATE_S, noise.weight_of(residual_s, hyper.toa_sigma_s), 0.0)
    sigma = float(np.sqrt(np.sum(weight * residual_s**2) / max(np.sum(weight), 1.0)))
    sigma = float(np.clip(sigma, kalman.Hyper.LOWER[2], sigma_cap_s))
    return dataclasses.replace(hyper, toa_sigma_s=sigma), weight


def _median_offsets(layout: ArrayLayout, floats: Sequence[MissionFloat], priors: kalman.KalmanPriors) -> NDArray:
    """theta at the tables as given but each source's offset at the median of its arrivals'
    residuals over every float: a source whose offset is tens of seconds off shifts all its
    arrivals alike, which the arrivals' weights, fitted per arrival, would otherwise take for
    multipath on every one of them (and the fit would never see the source)."""
    theta = np.zeros(layout.size)
    sources, residuals = [], []
    for f in floats:
        u = np.zeros(f.problem.n_unknowns)
        residuals.append(kalman.linearise(f.problem, u, np.ones(f.n_arrivals), priors).toa_residual_s)
        sources.append(layout.arrival_sources(f))
    where, r = np.concatenate(sources), np.concatenate(residuals)
    for g in range(len(layout.sources)):
        theta[layout.column(0, g)] = np.median(r[where == g])
    return theta


def fit_array(
    floats: Sequence[MissionFloat],
    config: Config,
    released: NDArray[np.bool_] | None = None,
    start: ArrayFit | None = None,
    priors: kalman.KalmanPriors = kalman.DEFAULT_PRIORS,
    iterations: int = ITERATIONS,
    map_floats: FloatMap = map,
) -> ArrayFit:
    """Gauss-Newton over the mission (module docstring), from `start` (a previous fit of
    the same floats) or the tables as given: each step reduces every float to the array
    block, solves it and back-substitutes (the step shortened where a source would move
    beyond `STEP_LIMITS`), then takes the arrivals' weights and each float's TOA sd refitted
    from the residuals the step started from (iteratively reweighted, one step behind).
    `released` (G, 5): the source unknowns under wide priors; `map_floats`: how the floats'
    tasks are mapped (in order)."""
    if start is None:
        layout = ArrayLayout.of(floats)
        floats = referred(list(floats), layout.sources, layout.mid_days)
        theta, own = _median_offsets(layout, floats, priors), [np.zeros(f.n_own) for f in floats]
        weight = [f.kept for f in floats]
    else:
        layout, floats, theta, own = start.layout, start.floats, start.theta, start.own
        weight = [w * f.kept for w, f in zip(start.weight, floats, strict=True)]
    s0 = 1.0 / config.model.sound_speed_m_s
    array_priors = ArrayPriors.of(layout, priors, s0, released)
    information = np.diag(1.0 / array_priors.sd() ** 2)
    columns = [layout.float_columns(f) for f in floats]
    noise = [MultipathEM(config.model, MULTIPATH_TOLERANCE, fit_multipath_em) for _ in floats]
    cap = SIGMA_CAP * config.model.toa_sigma_s
    for step in range(iterations + 1):
        last = step == iterations  # the covariance at the solution, no further move
        if step == 0 and start is not None and start.blocks and not last:
            steps = _restarted(start, noise, cap, map_floats)
        else:
            tasks = [
                FloatTask(f, np.concatenate([x, theta[c]]), w, c, priors, em, cap, refit=not last)
                for f, c, x, w, em in zip(floats, columns, own, weight, noise, strict=True)
            ]
            steps = list(map_floats(float_step, tasks))
        residuals = [s.residual_s for s in steps]
        solution = solve_mission([s.block for s in steps], information, -information @ theta)
        if last:
            break
        scale = _step_scale(solution.d_theta, layout)
        theta = theta + scale * solution.d_theta
        own = [x + scale * dx for x, dx in zip(own, solution.d_own, strict=True)]
        floats = [dataclasses.replace(f, hyper=s.hyper) for f, s in zip(floats, steps, strict=True)]
        weight = [s.weight * f.kept for s, f in zip(steps, floats, strict=True)]
        noise = [s.noise for s in steps]
    left_out = solution.left_out_steps()
    covariance, jackknife = solution.covariance(), solution.jackknife_covariance(left_out)
    outlying = outlying_pairs(left_out, layout, floats, weight)
    blocks = [s.block for s in steps]
    return ArrayFit(
        layout, floats, theta, covariance, jackknife, own, weight, residuals, array_priors, s0, outlying, blocks
    )


def floats_weighing(
    layout: ArrayLayout, floats: Sequence[MissionFloat], weight: Sequence[NDArray]
) -> NDArray[np.int64]:
    """(G,) per source the floats that weigh some of its arrivals (weight > 0)."""
    weighing = np.zeros((len(floats), len(layout.sources)), dtype=bool)
    for k, (f, w) in enumerate(zip(floats, weight, strict=True)):
        weighing[k, layout.arrival_sources(f)[w > 0]] = True
    return weighing.sum(axis=0).astype(np.int64)


def outlying_pairs(
    left_out: NDArray, layout: ArrayLayout, floats: Sequence[MissionFloat], weight: Sequence[NDArray]
) -> list[tuple[int, int]]:
    """(float, source) positions where the float is an outlier among the floats weighing the
    source's arrivals, in one of the source's offset, drift and position unknowns, tested
    together (`schur.outlying_together` on the left-out steps `left_out` (F, M)): equal
    Gaussian floats have a source's arrivals set aside in one fit of 100, whatever the
    number of its unknowns tested."""
    pairs = set()
    for g, touching in enumerate(floats_weighing(layout, floats, weight)):
        columns = layout.column(np.array(OUTLIER_BLOCKS), g)
        farthest, found = outlying_together(left_out[:, columns], np.full(len(columns), touching))
        pairs |= {(int(k), g) for k in farthest[found]}
    return sorted(pairs)
