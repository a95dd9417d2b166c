"""The whole method for one float: a loop over passes, calibrating between them.

    1. The robust first pass (`passes.robust_pass`): the TOA noise sd widened and the float
       clock in the state, so that timing errors of a few seconds and a wrong or missing
       end clock offset do not lose the float or move the track.
    2. Calibration (`rafostrack.calibrate`) from its confident labels: a batch Kalman
       smoother of the track with the timing parameters and the float clock in the state,
       its hyperparameters (drift, noise, clock wander) by maximum marginal likelihood.
    3. A pass with the calibrated model (`passes.feeding_pass`), then calibration again from
       that pass's labels and track, `[calibrate] iterations` calibrations in all (each
       pass's positions are better than the last, and so is the next calibration; its
       hyperparameter search starts where the last ended). After the first calibration's
       pass, with `[checks] source_scan`, the source scan (`run.schedule_scan`) may correct
       the beacon table, that pass and the calibration.
    4. The configured pass with the last calibration (`passes.final_pass`): the result. The
       position variance that the calibration leaves undetermined is added to its covariance.

Before step 1, with `[checks] enabled`: a listening window too short for the TOAs the
reader left out past it is lengthened and those TOAs taken back (`calibrate.window_check`),
and a launch fix far from anything the float could hear is weighed against the first days'
arrivals (`calibrate.launch_check`).

With `[calibrate] enabled = false`, one pass with the configured values. Values the user set
explicitly (config files, flags: `Config.explicit`) are kept as set. The float's result
(`TrackOutput`) is built once, when the passes are done.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import pandas as pd
from threadpoolctl import threadpool_limits

from ..calibrate import Calibration, calibrate
from ..calibrate.launch_check import launch_check
from ..calibrate.metadata_checks import CONTRADICTED, MetadataCheck, warnings_of
from ..calibrate.window_check import late_window_check
from ..domain import ArrivalRecord
from ..errors import Notice, WarningKind
from ..io.records import with_longer_window
from ..problem import FloatProblem
from ..summaries.estimates import Estimate
from .one_pass import run_pass
from .passes import FilterCounts, PassResult, PassSpec, Seconds, feeding_pass, final_pass, robust_pass
from .schedule_scan import scanned_schedules

Progress = Callable[[int, int, str], None]  # (done, total, which pass)


@dataclass(frozen=True)
class TrackOutput:
    """The float's result: the last pass, the problem it tracked (the beacon table and float
    as corrected, the calibrated model values), what calibration estimated (run.json's
    `calibration`) and the table values checked against the arrivals (`metadata_checks`),
    every warning of the method, and the seconds of all its passes and calibrations."""

    final: PassResult
    problem: FloatProblem
    warnings: tuple[str, ...]
    seconds: Seconds
    calibration: dict[str, Any] | None = None
    metadata_checks: tuple[dict[str, Any], ...] = ()

    @property
    def estimate(self) -> Estimate:
        return self.final.estimate

    @property
    def filtered(self) -> Estimate | None:
        return self.final.filtered

    @property
    def track(self) -> pd.DataFrame:
        return self.final.track

    @property
    def labels(self) -> pd.DataFrame:
        return self.final.labels

    @property
    def counts(self) -> FilterCounts:
        return self.final.counts

    @property
    def smoother(self) -> str:
        return self.final.smoother


@dataclass(frozen=True)
class _Calibrated:
    """Where the calibrating passes leave the method: the problem (its table as the source
    scan corrected it), the last calibration (None: too few confident arrivals in the first
    pass), the values the scan contradicted, and the seconds spent."""

    problem: FloatProblem
    calibration: Calibration | None
    scanned: list[MetadataCheck]
    seconds: Seconds


def track_record(
    problem: FloatProblem, record: ArrivalRecord, *, also_filtered: bool = False, progress: Progress | None = None
) -> TrackOutput:
    """Track one float's record with the configured method (module docstring); the keys the
    user set (`problem.config.explicit`) are not estimated. `progress(done, total, what)` is
    told of each filter step of each pass.

    The linear algebra of numpy and scipy runs on one BLAS thread (`threadpoolctl`): a
    multithreaded BLAS sums in another order on another core count, and calibration's
    values then move in their last bits and every later pass with them. The compiled
    kernels keep their own threads, which never change the bits (`model.parallel`)."""
    with threadpool_limits(limits=1, user_api="blas"):
        return _method(problem, record, also_filtered, progress)


def _method(
    problem: FloatProblem, record: ArrivalRecord, also_filtered: bool, progress: Progress | None
) -> TrackOutput:
    """`track_record`'s passes (module docstring)."""
    config = problem.config
    if not config.calibrate.enabled:
        result = run_pass(
            PassSpec.configured(problem, also_filtered=also_filtered), record, _told(progress, "pass 1 of 1")
        )
        return TrackOutput(result, problem, result.warnings, result.seconds)
    early: list[MetadataCheck] = []
    if config.checks.enabled:
        problem, record, early = _checked_before_tracking(problem, record)
    passes = 1 + config.calibrate.iterations
    calibrated = _calibrating_passes(problem, record, passes, progress)
    problem, calibration = calibrated.problem, calibrated.calibration
    name = _pass_name(passes, passes)
    if calibration is None:
        result = run_pass(PassSpec.configured(problem, also_filtered=also_filtered, name=name), record,
                          _told(progress, name))  # fmt: skip
        note = Notice(WarningKind.CALIBRATION, f"{problem.info.float_id}: too few confident arrivals to calibrate; "
                      "tracked with the configured values")  # fmt: skip
        return _float_output(result, problem, early, [], [note], None, calibrated.seconds)
    spec = final_pass(problem, calibration, also_filtered, name)
    result = run_pass(spec, record, _told(progress, name))
    scanned = {(c.id, c.field) for c in calibrated.scanned}
    checks = [*calibrated.scanned, *(c for c in calibration.checks if (c.id, c.field) not in scanned)]
    report = {**calibration.report, "passes": passes}
    return _float_output(result, spec.problem, early, checks, warnings_of(checks), report, calibrated.seconds)


def _calibrating_passes(
    problem: FloatProblem, record: ArrivalRecord, passes: int, progress: Progress | None
) -> _Calibrated:
    """Steps 1-3 (module docstring): the robust first pass, then `passes - 1` calibrations,
    each but the last followed by a pass with it; the source scan after the first."""
    name = _pass_name(1, passes)
    result = run_pass(robust_pass(problem, name), record, _told(progress, name))
    seconds = result.seconds
    calibration: Calibration | None = None
    scanned: list[MetadataCheck] = []
    scan = problem.config.checks.enabled and problem.config.checks.source_scan
    for number in range(2, passes + 1):
        started = time.perf_counter()
        start = calibration.hyper if calibration is not None else None
        fitted = calibrate(result.estimate, record, problem, start=start)
        seconds += Seconds(calibrate_s=time.perf_counter() - started)
        if fitted is None:
            break
        calibration = fitted
        if number == passes:  # the last calibration is the final pass's
            break
        name = _pass_name(number, passes)
        result = run_pass(feeding_pass(problem, calibration, name), record, _told(progress, name))
        seconds += result.seconds
        if number == 2 and scan:
            found = scanned_schedules(problem, record, calibration, result)
            problem, calibration, result, scanned = found.problem, found.calibration, found.result, found.findings
            seconds += found.seconds
    return _Calibrated(problem, calibration, scanned, seconds)


def _float_output(
    result: PassResult,
    problem: FloatProblem,
    early: Sequence[MetadataCheck],
    checks: Sequence[MetadataCheck],
    notes: Sequence[str],
    calibration: dict[str, Any] | None,
    seconds: Seconds,
) -> TrackOutput:
    """The float's result from its final pass: the checks made before tracking (`early`) in
    place of calibration's of the same field, which weighed the value the track started
    from, not the table's; their warnings first, then the pass's, then `notes`."""
    fields = {check.field for check in early}
    metadata = (*early, *(c for c in checks if c.field not in fields))
    warnings = (*(w for check in early if (w := check.warning())), *result.warnings, *notes)
    return TrackOutput(
        result, problem, warnings, seconds + result.seconds, calibration, tuple(c.as_json() for c in metadata)
    )


def _checked_before_tracking(
    problem: FloatProblem, record: ArrivalRecord
) -> tuple[FloatProblem, ArrivalRecord, list[MetadataCheck]]:
    """The problem and record to track after the checks made before tracking: a window too
    short lengthened (its late TOAs taken back), a launch fix in the wrong hemisphere
    replaced (`calibrate.launch_check`); those checks that found something, in that order."""
    early = []
    late = late_window_check(record, problem.info)
    if late is not None:
        assert isinstance(late.used, float)
        info = dataclasses.replace(problem.info, window_s=late.used)
        problem, record = (
            dataclasses.replace(problem, info=info),
            with_longer_window(record, late.used, info.max_signals),
        )
        early.append(late)
    checked = launch_check(problem, record)
    if checked is not None:
        check, problem = checked
        if check.outcome == CONTRADICTED:
            early.append(check)
    return problem, record, early


def _pass_name(number: int, passes: int) -> str:
    return f"pass {number} of {passes}"


def _told(progress: Progress | None, name: str) -> Callable[[int, int], None] | None:
    """The progress callback of one pass's filter steps ("pass 2 of 3")."""
    if progress is None:
        return None
    return lambda done, total: progress(done, total, name)
