"""The whole method for one float: a robust first pass, calibration, and passes with the calibrated model.

    1. First pass: filter and smoother with robust settings: the TOA noise sd widened to
       `[calibrate] first_pass_toa_sigma_s`, so that timing errors of a few seconds (a
       sound speed off by 0.5%, a source clock off its catalogue) do not lose the float,
       the float clock in the state (`motion.clock.ClockWalk`, `[calibrate]
       first_pass_clock_walk_s_per_sqrt_day`), so that a wrong or missing end clock offset
       in floats.csv does not move the track, and the configured drift model (broad by
       default).
    2. Calibration (`rafostrack.calibrate`) from its confident labels: a batch Kalman
       smoother of the track with the timing parameters and the float clock in the state,
       its hyperparameters (drift, noise, clock wander) by maximum marginal likelihood.
    3. Filter and smoother with the calibrated model; calibration again from that pass's
       labels and track, `[calibrate] iterations` times in all (each pass's positions are
       better than the last, and so is the next calibration; its hyperparameter search
       starts where the last ended); the last pass is the result.
       The position variance that the calibration leaves undetermined (`Calibration.
       nuisance_cov_km2`) is added to the last pass's covariance.

Before step 1, with `[checks] enabled`: a listening window too short for the TOAs the
reader left out past it is lengthened and those TOAs taken back (`calibrate.window_check`),
and a launch fix far from anything the float could hear is weighed against the first days'
arrivals (`calibrate.launch_check`).

With `[calibrate] enabled = false`, one pass with the configured values. Values the user set
explicitly (config files, flags: `Config.explicit`) are kept as set.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Sequence
from functools import partial
from typing import TypeVar

import numpy as np

from ..calibrate import Calibration, calibrate
from ..calibrate.launch_check import launch_check
from ..calibrate.metadata_checks import CONTRADICTED, MetadataCheck, warnings_of
from ..calibrate.source_scan import schedule_candidates, with_supported_schedule
from ..calibrate.window_check import late_window_check
from ..config import Config, with_overrides
from ..domain import ArrivalRecord
from ..io.records import with_longer_window
from ..motion import ClockWalk
from ..problem import FloatProblem
from .forked import Forked
from .one_pass import Tracker, TrackOutput

# FFBSm quantile points per step in the passes that feed calibration. Their track and labels
# are what calibration reads; on 512 points rather than the whole 1000-particle clouds their
# backward pass costs a quarter, and the sample's first-pass track moves by 0.08 km RMSE
# with the same labels (docs/decisions.md).
CALIBRATION_COLUMNS = 512
MAX_SCHEDULE_FINDINGS = 4  # sources whose schedule the scan corrects at most (`_scanned_schedules`)
SCHEDULE_TRIALS = 3  # candidates tracked again per scan (`_scanned_schedules`)

T = TypeVar("T")
PassProgress = Callable[[int], Callable[[int, int], None] | None]  # pass number -> its progress callback


def first_pass_config(config: Config) -> Config:
    """The robust first pass: the TOA noise sd widened (unless the user set it,
    `Config.explicit`), no calibration, `[calibrate] max_particles` (`calibration_pass`)."""
    sigma = config.model.toa_sigma_s
    if ("model", "toa_sigma_s") not in config.explicit:
        sigma = max(sigma, config.calibrate.first_pass_toa_sigma_s)
    return calibration_pass(with_overrides(config, model={"toa_sigma_s": sigma}))


def calibration_pass(config: Config) -> Config:
    """A pass that feeds calibration: at most `[calibrate] max_particles` particles, always
    smoothed (its labels and track then use the whole record, whatever the output asks for,
    so the result does not depend on it), by FFBSm alone (no backward filter: its track and
    labels, not the reported posterior, are what it gives; on `CALIBRATION_COLUMNS` points,
    `_feeding_calibration`)."""
    particles = min(config.filter.particles, config.calibrate.max_particles)
    return with_overrides(config, filter={"particles": particles}, smoother={"enabled": True, "two_filter": False})


def track_record(
    problem: FloatProblem,
    record: ArrivalRecord,
    *,
    also_filtered: bool = False,
    progress: Callable[[int, int, str], None] | None = None,
) -> TrackOutput:
    """Track one float's record with the configured method (module docstring); the keys the
    user set (`problem.config.explicit`) are not estimated. `progress(done, total, what)` is
    told of each filter step of each pass. The output's `problem` is the one its final pass
    tracked."""
    config = problem.config
    passes = 1 + config.calibrate.iterations if config.calibrate.enabled else 1
    told = _pass_progress(progress, passes)
    if config.calibrate.enabled:
        late = late_window_check(record, problem.info) if config.checks.enabled else None
        if late is not None:
            problem, record = _with_window_of(late, problem, record)
        checked = launch_check(problem, record) if config.checks.enabled else None
        tracked = problem if checked is None else checked[1]
        out, final = _calibrated_method(tracked, record, passes, told, also_filtered)
        if checked is not None and checked[0].outcome == CONTRADICTED:
            out = _with_early_check(out, checked[0])
        if late is not None:
            out = _with_early_check(out, late)
    else:
        out = Tracker.from_problem(problem).track(record, also_filtered=also_filtered, progress=told(1))
        final = problem
    return dataclasses.replace(out, problem=final)


def _with_window_of(
    check: MetadataCheck, problem: FloatProblem, record: ArrivalRecord
) -> tuple[FloatProblem, ArrivalRecord]:
    """The problem and record with the window `check` supports, its late TOAs taken back."""
    assert isinstance(check.used, float)
    info = dataclasses.replace(problem.info, window_s=check.used)
    return dataclasses.replace(problem, info=info), with_longer_window(record, check.used, info.max_signals)


def _with_early_check(out: TrackOutput, check: MetadataCheck) -> TrackOutput:
    """`out` with a check made before tracking (the gross launch check,
    `calibrate.launch_check`; a window too short, `calibrate.window_check`) in place of
    calibration's of the same field, which weighed the value the track started from, not
    the table's."""
    checks = [c for c in out.metadata_checks if c["field"] != check.field]
    warning = check.warning()
    return dataclasses.replace(
        out,
        metadata_checks=(check.as_json(), *checks),
        warnings=[*([warning] if warning else []), *out.warnings],
    )


def _pass_progress(progress: Callable[[int, int, str], None] | None, passes: int) -> PassProgress:
    """Pass number -> the progress callback of its filter steps ("pass 2 of 3")."""

    def told(number: int) -> Callable[[int, int], None] | None:
        if progress is None:
            return None
        return lambda done, total: progress(done, total, f"pass {number} of {passes}")

    return told


def _calibrated_method(
    problem: FloatProblem, record: ArrivalRecord, passes: int, told: PassProgress, also_filtered: bool
) -> tuple[TrackOutput, FloatProblem]:
    """The whole method (module docstring): the calibrating passes, then the last pass with
    the last calibration (or, with none, with the configured values); the output and the
    problem the last pass tracked."""
    run = _calibrating_passes(problem, record, told)
    calibration, problem = run.calibration, run.problem
    if calibration is None:
        note = f"{problem.info.float_id}: too few confident arrivals to calibrate; tracked with the configured values"
        out = Tracker.from_problem(problem).track(record, also_filtered=also_filtered, progress=told(passes))
        return dataclasses.replace(out, warnings=[*out.warnings, note]), problem
    final = calibration.calibrated(problem)
    out = Tracker.from_problem(final).track(
        record, also_filtered=also_filtered, extra_cov=calibration.nuisance_cov_at, progress=told(passes)
    )
    report = {**calibration.report, "passes": passes}
    scanned = {(c.id, c.field) for c in run.scanned}
    checks = [*run.scanned, *(c for c in calibration.checks if (c.id, c.field) not in scanned)]
    out = dataclasses.replace(
        out,
        calibration=report,
        metadata_checks=tuple(check.as_json() for check in checks),
        warnings=[*out.warnings, *warnings_of(checks)],
        filter_s=run.spent["filter_s"] + out.filter_s,
        smoother_s=run.spent["smoother_s"] + out.smoother_s,
        calibrate_s=run.spent["calibrate_s"],
    )
    return out, final


@dataclasses.dataclass(frozen=True)
class _CalibratingPasses:
    """What the passes before the last give it: the last calibration (None: too few confident
    arrivals in the first pass), the problem it calibrated (the beacon table corrected where
    the source scan contradicted it), those contradicted values, and the seconds spent."""

    calibration: Calibration | None
    problem: FloatProblem
    scanned: list[MetadataCheck]
    spent: dict[str, float]


def _calibrating_passes(problem: FloatProblem, record: ArrivalRecord, told: PassProgress) -> _CalibratingPasses:
    """Steps 1-2 and the passes between calibrations: the robust first pass, then
    `[calibrate] iterations` calibrations, each but the last followed by a pass with it. The
    pass after the first calibration feeds the source scan (`_scanned_schedules`), which may
    correct the beacon table, that pass and the calibration."""
    config = problem.config
    out = _first_pass(problem).track(record, progress=told(1))
    spent = {"filter_s": out.filter_s, "smoother_s": out.smoother_s, "calibrate_s": 0.0}
    calibration: Calibration | None = None
    scanned: list[MetadataCheck] = []
    for iteration in range(config.calibrate.iterations):
        started = time.perf_counter()
        start = calibration.hyper if calibration is not None else None
        fitted = calibrate(out.estimate, record, problem, start=start)
        spent["calibrate_s"] += time.perf_counter() - started
        if fitted is None:
            break
        calibration = fitted
        if iteration < config.calibrate.iterations - 1:
            out = _calibrated_pass(problem, calibration, record, spent, told(iteration + 2))
            if iteration == 0 and config.checks.enabled and config.checks.source_scan:
                problem, out, calibration, scanned = _scanned_schedules(problem, record, calibration, out, spent)
    return _CalibratingPasses(calibration, problem, scanned, spent)


def _first_pass(problem: FloatProblem) -> Tracker:
    """The robust first pass's tracker (step 1)."""
    robust = problem.with_config(first_pass_config(problem.config))
    return _clock_in_state(_feeding_calibration(Tracker.from_problem(robust)), problem.config)


def _calibrated_pass(
    problem: FloatProblem,
    calibration: Calibration,
    record: ArrivalRecord,
    spent: dict[str, float],
    progress: Callable[[int, int], None] | None = None,
    checks: list[MetadataCheck] | None = None,
) -> TrackOutput:
    """A pass that feeds calibration, tracked with `calibration` (the beacon table with
    the schedule of `checks` where given: a source scan's candidate); `spent` adds its
    seconds."""
    calibrated = calibration.calibrated(problem.with_config(calibration_pass(problem.config)))
    if checks:
        calibrated = dataclasses.replace(calibrated, beacons=with_supported_schedule(calibrated.beacons, checks))
    out = _feeding_calibration(Tracker.from_problem(calibrated)).track(
        record, extra_cov=calibration.nuisance_cov_at, progress=progress
    )
    spent["filter_s"] += out.filter_s
    spent["smoother_s"] += out.smoother_s
    return out


def _scanned_schedules(
    problem: FloatProblem, record: ArrivalRecord, calibration: Calibration, out: TrackOutput, spent: dict[str, float]
) -> tuple[FloatProblem, TrackOutput, Calibration, list[MetadataCheck]]:
    """Sources whose schedule in the table the arrivals contradict (`calibrate.source_scan`),
    one at a time: the `SCHEDULE_TRIALS` strongest candidates along the track of `out` (a
    pass tracked with `calibration`), each a different source, are tried by tracking the
    record again with the same calibration and the candidate's schedule. A trial that
    raises the record's evidence (the filter's sum of log p(y_t | y_1..t-1) over the
    windows) by more than `[checks] z_score`^2 / 2 (the likelihood-ratio counterpart of z
    sds) makes its candidate a contender. Each contender's table is calibrated and tracked
    again (`_refitted_pass`), and of several the best is kept (`_contest`): the trials
    share the calibration fitted to the table as given, which the wrong schedule has
    pulled, and there a shift of another source can explain the signals better than the
    true fix does. Another candidate within the margin of the kept one explains the
    arrivals as well: the finding names its source too (`MetadataCheck.other_sources`: the
    arrivals cannot tell which source's schedule is wrong). The corrected table is then
    scanned again, each source at most once. The problem, pass and calibration to go on
    with, and the contradicted values kept. `spent` adds the seconds."""
    threshold = problem.config.checks.z_score**2 / 2
    found: list[MetadataCheck] = []
    done: set[str] = set()  # the sources a finding named
    for _ in range(MAX_SCHEDULE_FINDINGS):
        started = time.perf_counter()
        candidates = [
            c.checks
            for c in schedule_candidates(problem, calibration.calibrated(problem), out.estimate, record)
            if not done & {check.id for check in c.checks}
        ][:SCHEDULE_TRIALS]
        spent["calibrate_s"] += time.perf_counter() - started
        trials = _trials(problem, calibration, record, spent, candidates)
        gains = np.array([_record_evidence(trial) - _record_evidence(out) for trial in trials])
        contenders = [int(k) for k in np.argsort(-gains, kind="stable") if gains[k] > threshold]
        jobs = [partial(_refitted_pass, problem, candidates[k], trials[k], record, calibration) for k in contenders]
        refits = _each_beside(jobs, spent)
        scored = {k: refit for k, refit in zip(contenders, refits, strict=True) if refit is not None}
        if not scored:
            break
        best, close = _contest(scored, threshold, record, spent)
        problem, calibration, out = scored[best]
        close += [k for k in range(len(gains)) if k not in scored and gains[best] - gains[k] <= threshold]
        others = tuple(candidates[k][0].id for k in sorted(close))
        checks = [dataclasses.replace(check, other_sources=others) for check in candidates[best]]
        found += checks
        done |= {check.id for check in checks} | set(others)
    return problem, out, calibration, found


def _contest(
    scored: dict[int, tuple[FloatProblem, Calibration, TrackOutput]],
    margin: float,
    record: ArrivalRecord,
    spent: dict[str, float],
) -> tuple[int, list[int]]:
    """The contender kept, and those that explain the arrivals as well (within `margin`),
    of the refitted passes `scored` (contender -> its table, calibration and pass). One
    contender: kept. Several: each pass's evidence is one filter run's estimate, whose
    Monte Carlo error is several nats, so each table is tracked again with another seed
    (`[filter] seed` + 1, half of them beside); the contender of highest mean evidence over
    the two runs is kept, and another is close to it if within `margin` of it, or better,
    in either run. `spent` adds the seconds."""
    if len(scored) == 1:
        (only,) = scored
        return only, []
    order = list(scored)
    again = _each_beside(
        [partial(_calibrated_pass, _reseeded(scored[k][0]), scored[k][1], record) for k in order], spent
    )
    runs = {k: np.array([_record_evidence(scored[k][2]), _record_evidence(rerun)])
            for k, rerun in zip(order, again, strict=True)}  # fmt: skip
    best = max(order, key=lambda k: runs[k].mean())
    return best, [k for k in order if k != best and bool(np.any(runs[best] - runs[k] <= margin))]


def _reseeded(problem: FloatProblem) -> FloatProblem:
    """`problem` with `[filter] seed` + 1: the same method, other random draws."""
    return problem.with_config(with_overrides(problem.config, filter={"seed": problem.config.filter.seed + 1}))


def _refitted_pass(
    problem: FloatProblem,
    checks: list[MetadataCheck],
    trial: TrackOutput,
    record: ArrivalRecord,
    calibration: Calibration,
    spent: dict[str, float],
) -> tuple[FloatProblem, Calibration, TrackOutput] | None:
    """The table with the schedule of `checks`, calibrated from its `trial` pass (the
    search starting at `calibration`'s hyperparameters) and tracked with that calibration;
    None when the trial has too few confident arrivals to calibrate. `spent` adds the
    seconds."""
    started = time.perf_counter()
    tried = dataclasses.replace(problem, beacons=with_supported_schedule(problem.beacons, checks))
    refitted = calibrate(trial.estimate, record, tried, start=calibration.hyper)
    spent["calibrate_s"] += time.perf_counter() - started
    if refitted is None:
        return None
    return tried, refitted, _calibrated_pass(tried, refitted, record, spent)


def _trials(
    problem: FloatProblem,
    calibration: Calibration,
    record: ArrivalRecord,
    spent: dict[str, float],
    candidates: list[list[MetadataCheck]],
) -> list[TrackOutput]:
    """The pass of each candidate schedule (`_calibrated_pass` with its checks, the same
    calibration), in the candidates' order (`_each_beside`). `spent` adds the seconds."""
    return _each_beside([partial(_calibrated_pass, problem, calibration, record, checks=c) for c in candidates], spent)


def _each_beside(jobs: Sequence[Callable[[dict[str, float]], T]], spent: dict[str, float]) -> list[T]:
    """job(spent) for each job, in order, the later half computed beside the earlier half
    where a core is idle (`run.forked`): each job is its own computation, the same bits.
    `spent` adds the seconds of all of them."""
    half = (len(jobs) + 1) // 2

    def later() -> tuple[list[T], dict[str, float]]:
        theirs = dict.fromkeys(spent, 0.0)
        return [job(theirs) for job in jobs[half:]], theirs

    with Forked(later, fork=len(jobs) > half) as beside:
        results = [job(spent) for job in jobs[:half]]
        rest, theirs = beside.result()
    for part, seconds in theirs.items():
        spent[part] += seconds
    return results + rest


def _record_evidence(out: TrackOutput) -> float:
    """log p(y_1..T) of a pass's filter: the sum of its windows' log p(y_t | y_1..t-1)."""
    return float(np.nansum(out.estimate.track["loglik"].to_numpy()))


def _clock_in_state(tracker: Tracker, config: Config) -> Tracker:
    """`tracker` with each particle's correction to the table's float clock in its state
    (`motion.clock.ClockWalk`: a walk of `[calibrate] first_pass_clock_walk_s_per_sqrt_day`
    from `[fixes] clock_offset_sd_s` at launch), as the first pass tracks; unchanged when
    the walk is 0."""
    walk = config.calibrate.first_pass_clock_walk_s_per_sqrt_day
    if walk <= 0:
        return tracker
    return dataclasses.replace(tracker, motion=ClockWalk(tracker.motion, walk, config.fixes.clock_offset_sd_s))


def _feeding_calibration(tracker: Tracker) -> Tracker:
    """`tracker` (of a `calibration_pass` config) with FFBSm on `CALIBRATION_COLUMNS` points."""
    return dataclasses.replace(tracker, ffbsm_columns=CALIBRATION_COLUMNS)
