"""One pass assembled from its components: filter, smooth (unless disabled), summarise.

`Tracker.for_pass` picks each component from its registry (motion model, arrival
likelihood and its engine, resampling scheme) for one pass (`run.passes.PassSpec`);
`Tracker.from_problem` for the pass the user configured. `Tracker.track` runs the float's
record in memory, with no file I/O, and gives a `PassResult`; `run_pass` does both.
`run.method.track_record` runs the method's passes and `one_float` reads inputs and writes
outputs around them; tests, benchmarks and papers call them directly.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..config import AmbiguityConfig, Config
from ..context.floats import context_factors
from ..domain import ArrivalRecord, Cloud, FloatInfo, Particles, PositionFix
from ..errors import Notice
from ..filtering.filter import FilterResult, FilterSettings, ParticleFilter, Step, float_rng, observations
from ..filtering.guided import Guide
from ..filtering.recovery import RecoverySettings
from ..likelihoods import (
    ArrivalLikelihood,
    MoveFactor,
    PositionFixLikelihood,
    arrivals_from_config,
)
from ..motion import ClockWalk, JumpMixture, MotionModel, motion_from_config
from ..problem import FloatProblem
from ..smoothing.ffbsm import Smoothed, column_points, smooth
from ..smoothing.split import Split, split_of, split_warning
from ..smoothing.two_filter import JOIN_COLUMNS, forward_view, two_filter_smooth
from ..summaries.estimates import Estimate, EstimateBuilder, Regions
from .forked import Forked
from .passes import FilterCounts, NuisanceCov, PassResult, PassSpec, Seconds, Smoothing


def _motion(config: Config) -> MotionModel:
    """The configured drift model, made robust by a jump component when recovery is on."""
    base = motion_from_config(config.motion)
    rec = config.recovery
    if not rec.enabled or rec.jump_rate_per_day == 0:
        return base
    return JumpMixture(base, rec.jump_rate_per_day, rec.jump_sd_km)


def _recovery(config: Config) -> RecoverySettings | None:
    rec = config.recovery
    if not rec.enabled:
        return None
    return RecoverySettings(
        search_radius_km=rec.search_radius_km, fraction=rec.reseed_fraction, check_every=rec.check_every
    )


@dataclass(frozen=True)
class Tracker:
    """One float's tracker: its components and the few settings that join them."""

    info: FloatInfo
    beacon_ids: np.ndarray
    motion: MotionModel
    arrivals: ArrivalLikelihood
    settings: FilterSettings
    launch_sd_km: float
    end_fix: PositionFix | None
    smoothing: Smoothing
    ambiguity: AmbiguityConfig
    seed: int
    recovery: RecoverySettings | None = None
    factors: tuple[MoveFactor, ...] = ()
    guide: Guide | None = None  # part of each window's cloud drawn guided by it (`rafostrack.filtering.guided`)

    @classmethod
    def for_pass(cls, spec: PassSpec) -> Tracker:
        """The tracker of one pass: its problem's beacons and float, the components its
        configuration asks for (with the pass's model values, seed and particles), its
        smoothing, and the float clock's walk in the state when the pass asks for one."""
        beacons, info, config = spec.problem.beacons, spec.problem.info, spec.tracking_config()
        use_end = config.fixes.use_end_fix and info.has_end_fix
        motion = _motion(config)
        if spec.clock_walk_s_per_sqrt_day > 0:
            motion = ClockWalk(motion, spec.clock_walk_s_per_sqrt_day, config.fixes.clock_offset_sd_s)
        return cls(
            info=info,
            beacon_ids=beacons.beacon_id,
            motion=motion,
            arrivals=arrivals_from_config(beacons, info, config),
            settings=FilterSettings.from_config(config.filter),
            launch_sd_km=config.fixes.launch_sd_km,
            end_fix=PositionFix(info.end_time, info.end_lat, info.end_lon, config.fixes.end_sd_km) if use_end else None,
            smoothing=spec.smoothing,
            ambiguity=config.ambiguity,
            seed=spec.seed,
            recovery=_recovery(config),
            factors=context_factors(config, beacons, info),
            guide=Guide(config.filter.guided_fraction) if config.filter.guided_fraction > 0 else None,
        )

    @classmethod
    def from_problem(cls, problem: FloatProblem) -> Tracker:
        """The tracker of the pass the user configured (`PassSpec.configured`)."""
        return cls.for_pass(PassSpec.configured(problem))

    def _regions(self) -> Regions | None:
        """Region labels from the first factor that parts the sea (context), if any."""
        if not self.factors:
            return None

        def regions(particles: Particles) -> NDArray[np.int64] | None:
            for factor in self.factors:
                labels = factor.regions(particles)
                if labels is not None:
                    return labels
            return None

        return regions

    def run_filter(
        self,
        record: ArrivalRecord,
        *,
        label_probs: bool = True,
        keep: bool = True,
        on_step: Callable[[Step], None] | None = None,
        backward: bool = False,
    ) -> FilterResult:
        """The forward filter over the record (and the end fix), with the float's own
        generator; see `ParticleFilter.run` for `keep` and `on_step`. `backward`: the filter
        from the end fix back to the first window, with the drift reversed (its own
        generator, at most `smoothing.backward_particles` particles; `rafostrack.smoothing.two_filter`)."""
        info = self.info
        motion, stream, settings = self.motion, info.float_id, self.settings
        start = PositionFix(info.launch_time, info.launch_lat, info.launch_lon, self.launch_sd_km)
        events = observations(record.windows, self.end_fix)
        if backward:
            if self.end_fix is None:
                raise ValueError(f"{info.float_id}: a backward filter starts from the end fix, and there is none")
            motion, stream = self.motion.reversed(), f"{info.float_id} backward"
            start, events = self.end_fix, list(reversed(record.windows))
            if 0 < self.smoothing.backward_particles < settings.particles:
                settings = dataclasses.replace(settings, particles=self.smoothing.backward_particles)
        fixes = PositionFixLikelihood(info.float_id)
        pf = ParticleFilter(
            motion,
            self.arrivals,
            fixes,
            settings,
            label_probs=label_probs,
            recovery=self.recovery,
            factors=self.factors,
            guide=self.guide,
        )
        return pf.run(start, events, float_rng(self.seed, stream), keep=keep, on_step=on_step)

    def _joins_two_filters(self, record: ArrivalRecord) -> bool:
        """Whether the smoother joins a backward filter (`two_filter`): configured, an end fix
        after every window, no move factors (the backward filter would need them reversed)
        and no float clock in the state (the backward filter would need it at the end)."""
        end = self.end_fix
        return (
            self.smoothing.two_filter
            and end is not None
            and not self.factors
            and not isinstance(self.motion, ClockWalk)
            and all(w.time <= end.time for w in record.windows)
            and len(record.windows) > 0
        )

    def _run_kept(
        self,
        record: ArrivalRecord,
        columns: int,
        *,
        label_probs: bool = False,
        on_step: Callable[[Step], None] | None = None,
        backward: bool = False,
    ) -> FilterResult:
        """`run_filter`, keeping of each step what a smoother reads: its cloud on at most
        `columns` quantile points of its weights (`ffbsm.column_points`, where the
        smoothers would take them anyway), so that the history's memory does not grow with
        the particle count. `on_step` sees each whole step."""
        kept: list[Step] = []

        def keep(step: Step) -> None:
            if on_step is not None:
                on_step(step)
            kept.append(dataclasses.replace(step, cloud=column_points(step.cloud, columns)[0]))

        run = self.run_filter(record, label_probs=label_probs, keep=False, on_step=keep, backward=backward)
        return dataclasses.replace(run, steps=kept)

    def track(
        self,
        record: ArrivalRecord,
        *,
        also_filtered: bool = False,
        extra_cov: NuisanceCov | None = None,
        progress: Callable[[int, int], None] | None = None,
    ) -> PassResult:
        """Filter the record, then smooth if the pass smooths, and summarise. `extra_cov(times)`
        gives a (n, 2, 2) covariance (km^2) to add to each window's position covariance:
        what the filter's model does not represent (`Calibration.nuisance_cov_at`).
        `progress(done, total)` is told of each filter step.

        Without smoothing, each step is summarised as the filter makes it and then dropped,
        so memory does not grow with the record. Smoothing keeps every step's cloud on at
        most `smoothing.ffbsm_columns` quantile points of its weights (FFBSm), or each
        filter's on `two_filter.JOIN_COLUMNS` (`_run_kept`): at most 80 KB per window with
        a velocity, whatever the particle count. The two-filter smoother's backward filter
        runs beside the forward one where a core is idle (`_backward`)."""
        started = time.perf_counter()
        filtered = self._builder("filtered")
        summarised = filtered if also_filtered or not self.smoothing.enabled else None
        on_step = self._on_step(record, summarised, extra_cov, progress)
        if not self.smoothing.enabled:
            run = self.run_filter(record, keep=False, on_step=on_step)
            estimate = filtered.result()
            seconds = Seconds(filter_s=time.perf_counter() - started)
            return PassResult(estimate, estimate, _counts(run, filtered), tuple(run.warnings), "none", seconds)
        two_filter = self._joins_two_filters(record)
        with self._backward(record, two_filter) as backward:
            columns = JOIN_COLUMNS if two_filter else self.smoothing.ffbsm_columns
            run = self._run_kept(record, columns, label_probs=also_filtered, on_step=on_step)
            filter_s = time.perf_counter() - started
            started = time.perf_counter()
            back = backward.result()
        estimate, split = self._smoothed_estimate(run, back, extra_cov)
        seconds = Seconds(filter_s=filter_s, smoother_s=time.perf_counter() - started)
        return PassResult(
            estimate,
            filtered.result() if also_filtered else None,
            _counts(run),
            (*run.warnings, *([split] if split is not None else [])),
            "two_filter" if two_filter else "ffbsm",
            seconds,
        )

    def _backward(self, record: ArrivalRecord, two_filter: bool) -> Forked[FilterResult | None]:
        """The two-filter smoother's backward filter (kept as `_run_kept` keeps), None without
        it; in a forked child beside the forward filter where a core is idle (`run.forked`),
        the same bits as after it."""
        return Forked(
            lambda: self._run_kept(record, JOIN_COLUMNS, backward=True) if two_filter else None, fork=two_filter
        )

    def _on_step(
        self,
        record: ArrivalRecord,
        filtered: EstimateBuilder | None,
        extra_cov: NuisanceCov | None,
        progress: Callable[[int, int], None] | None,
    ) -> Callable[[Step], None]:
        """What the filter does with each step it makes: summarise it into `filtered` (when
        given; with `extra_cov` at the step's time), then tell `progress` of each window (the
        end fix's step is not a window: a 729-window record counts to 729)."""
        total = len(record.windows)
        done = iter(range(1, total + 1))

        def on_step(step: Step) -> None:
            if filtered is not None:
                at = np.array([step.cloud.time], dtype="datetime64[ns]")
                filtered.add(step, extra_cov_km2=None if extra_cov is None else extra_cov(at)[0])
            if progress is not None and step.window is not None:
                progress(next(done), total)

        return on_step

    def _smoothed_estimate(
        self,
        run: FilterResult,
        back: FilterResult | None,
        extra_cov: NuisanceCov | None,
    ) -> tuple[Estimate, Notice | None]:
        """The smoothed estimate of a kept run: FFBSm on the forward filter's clouds, or, given
        the backward filter's run `back` (`_joins_two_filters`), both filters joined
        (`rafostrack.smoothing.two_filter`), with the warning of the windows they held apart
        (`smoothing.split`). Each window is joined and summarised on its own: the later half
        of the steps beside the earlier half where a core is idle (`run.forked`), the same bits."""
        steps = run.steps
        warning = None
        if back is None:
            smoothed = smooth([s.cloud for s in steps], self.motion, max_columns=self.smoothing.ffbsm_columns)

            def part(among: range) -> EstimateBuilder:
                return self._summarised([steps[k] for k in among], smoothed.part(among), extra_cov)
        else:
            steps, inputs = self._join_inputs(run, back)
            splits = [split_of(f, b) for f, b in zip(inputs[0][1:], inputs[2][:-1], strict=True)]
            warning = split_warning(np.array([s.cloud.time for s in steps]), splits)

            def part(among: range) -> EstimateBuilder:
                clouds, smoothed = two_filter_smooth(*inputs, self.motion, windows=among)
                joined = [dataclasses.replace(steps[k], cloud=c) for k, c in zip(among, clouds, strict=True)]
                return self._summarised(joined, smoothed, extra_cov, [splits[k] for k in among])

        half, count = len(steps) // 2, len(steps)
        with Forked(lambda: part(range(half, count)).rows(), fork=half > 0) as later:
            builder = part(range(half))
            builder.extend(later.result())
        return builder.result(), warning

    def _join_inputs(
        self, run: FilterResult, back: FilterResult
    ) -> tuple[list[Step], tuple[list[Cloud], list[float], list[Cloud], list[float]]]:
        """The forward filter's steps at the windows (its last is the end fix) and what
        `two_filter_smooth` joins them from: each filter's clouds and step evidences, the
        backward filter's in time order."""
        steps, end = run.steps[:-1], run.steps[-1]
        if run.prior is None or back.prior is None or any(s.window is None for s in steps) or end.window is not None:
            raise ValueError(f"{self.info.float_id}: the forward filter's steps are not the windows and the end fix")
        forward = [run.prior, *(s.cloud for s in steps)]
        backward = forward_view([back.prior, *(s.cloud for s in back.steps)])
        return steps, (forward, [s.loglik for s in steps], backward, [s.loglik for s in reversed(back.steps)])

    def _summarised(
        self,
        steps: list[Step],
        smoothed: Smoothed,
        extra_cov: NuisanceCov | None,
        splits: list[Split | None] | None = None,
    ) -> EstimateBuilder:
        """`steps` summarised under their `smoothed` weights, labels from the smoothed
        clouds; each window's position covariance with the smoother's kernel covariance and
        `extra_cov` added; `splits`: the windows the two filters held apart."""
        times = np.array([s.cloud.time for s in steps], dtype="datetime64[ns]")
        nuisance = extra_cov(times) if extra_cov is not None else np.zeros((len(times), 2, 2))
        kernels = np.array(smoothed.kernel_cov_km2).reshape(-1, 2, 2)
        builder = self._builder("smoothed")
        return builder.add_steps(steps, smoothed, self.arrivals.label_probs, nuisance + kernels, splits)

    def _builder(self, kind: str) -> EstimateBuilder:
        """An empty estimate of this float, `kind` "filtered" or "smoothed"."""
        return EstimateBuilder(self.info.float_id, self.beacon_ids, self.ambiguity, kind, self._regions())


def _counts(run: FilterResult, builder: EstimateBuilder | None = None) -> FilterCounts:
    """What a filter run counted (ESS per window from the builder when the run kept no steps)."""
    ess = builder.window_ess if builder is not None else tuple(s.ess for s in run.steps if s.window is not None)
    return FilterCounts(run.n_resamples, tuple(ess), run.n_checks, run.n_reseeds)


def run_pass(spec: PassSpec, record: ArrivalRecord, progress: Callable[[int, int], None] | None = None) -> PassResult:
    """Track `record` as `spec` says (`Tracker.for_pass`); `progress(done, total)` is told of
    each filter step."""
    tracker = Tracker.for_pass(spec)
    return tracker.track(record, also_filtered=spec.also_filtered, extra_cov=spec.extra_cov, progress=progress)
