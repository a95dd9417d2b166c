"""The source scan between the method's first two calibrations: schedules the arrivals contradict.

A source in the wrong transmission slot, tens of seconds off, or with an active period that
ends too soon, is found by scanning where its signals do arrive along a pass's track
(`calibrate.source_scan.schedule_candidates`). Each candidate is tried as a pass of its own
(`passes.feeding_pass` with its schedule) and judged by the record's evidence (the filter's
sum of log p(y_t | y_1..t-1) over the windows, `PassResult.evidence`):

1. The `SCHEDULE_TRIALS` strongest candidates along the track, each a different source, are
   tracked with the same calibration and the candidate's schedule. A trial that raises the
   record's evidence by more than `[checks] z_score`^2 / 2 (the likelihood-ratio
   counterpart of z sds) makes its candidate a contender.
2. Each contender's table is calibrated from its trial and tracked again (`_refitted`): the
   trials share the calibration fitted to the table as given, which the wrong schedule has
   pulled, and there a shift of another source can explain the signals better than the
   true fix does.
3. Of several refitted contenders the best is kept (`_contest`); another within the margin
   explains the arrivals as well, and the finding names its source too
   (`MetadataCheck.other_sources`: the arrivals cannot tell which source's schedule is wrong).

The corrected table is then scanned again, each source at most once, at most
`MAX_SCHEDULE_FINDINGS` times. Independent passes run half beside the other half where a
core is idle (`each_beside`): each is its own computation, the same bits.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from functools import partial
from typing import TypeVar

import numpy as np

from ..calibrate import Calibration, calibrate
from ..calibrate.metadata_checks import MetadataCheck
from ..calibrate.source_scan import schedule_candidates, with_supported_schedule
from ..domain import ArrivalRecord
from ..problem import FloatProblem
from .forked import Forked
from .one_pass import run_pass
from .passes import PassResult, Seconds, feeding_pass

MAX_SCHEDULE_FINDINGS = 4  # sources whose schedule the scan corrects at most
SCHEDULE_TRIALS = 3  # candidates tracked again per scan

T = TypeVar("T")


@dataclass(frozen=True)
class Scanned:
    """What the scan leaves the method: the problem (its table with the schedules found),
    the calibration and pass to go on with, the contradicted values, and its seconds."""

    problem: FloatProblem
    calibration: Calibration
    result: PassResult
    findings: list[MetadataCheck]
    seconds: Seconds


@dataclass(frozen=True)
class _Refit:
    """A contender's table, its calibration and the pass tracked with it."""

    problem: FloatProblem
    calibration: Calibration
    result: PassResult


def scanned_schedules(
    problem: FloatProblem, record: ArrivalRecord, calibration: Calibration, result: PassResult
) -> Scanned:
    """Sources whose schedule in the table the arrivals contradict, one at a time (module
    docstring), along the track of `result` (a pass tracked with `calibration`)."""
    threshold = problem.config.checks.z_score**2 / 2
    found: list[MetadataCheck] = []
    done: set[str] = set()  # the sources a finding named
    seconds = Seconds()
    for _ in range(MAX_SCHEDULE_FINDINGS):
        started = time.perf_counter()
        candidates = [
            c.checks
            for c in schedule_candidates(problem, calibration.calibrated(problem), result.estimate, record)
            if not done & {check.id for check in c.checks}
        ][:SCHEDULE_TRIALS]
        seconds += Seconds(calibrate_s=time.perf_counter() - started)
        trials = each_beside(
            [partial(run_pass, feeding_pass(problem, calibration, schedule=c), record) for c in candidates]
        )
        gains = np.array([trial.evidence - result.evidence for trial in trials])
        contenders = [int(k) for k in np.argsort(-gains, kind="stable") if gains[k] > threshold]
        refits = each_beside(
            [partial(_refitted, problem, candidates[k], trials[k], record, calibration) for k in contenders]
        )
        seconds += _sum(trial.seconds for trial in trials) + _sum(spent for _, spent in refits)
        scored = {k: refit for k, (refit, _) in zip(contenders, refits, strict=True) if refit is not None}
        if not scored:
            break
        best, close, contest_s = _contest(scored, threshold, record)
        seconds += contest_s
        problem, calibration, result = scored[best].problem, scored[best].calibration, scored[best].result
        close += [k for k in range(len(gains)) if k not in scored and gains[best] - gains[k] <= threshold]
        others = tuple(candidates[k][0].id for k in sorted(close))
        checks = [dataclasses.replace(check, other_sources=others) for check in candidates[best]]
        found += checks
        done |= {check.id for check in checks} | set(others)
    return Scanned(problem, calibration, result, found, seconds)


def _contest(scored: dict[int, _Refit], margin: float, record: ArrivalRecord) -> tuple[int, list[int], Seconds]:
    """The contender kept, those that explain the arrivals as well (within `margin`), of the
    refitted passes `scored`, and the seconds the contest took. One contender: kept.
    Several: each pass's evidence is one filter run's estimate, whose Monte Carlo error is
    several nats, so each table is tracked again with the next seed (half of them beside);
    the contender of highest mean evidence over the two runs is kept, and another is close
    to it if within `margin` of it, or better, in either run."""
    if len(scored) == 1:
        (only,) = scored
        return only, [], Seconds()
    order = list(scored)
    again = each_beside(
        [partial(run_pass, feeding_pass(scored[k].problem, scored[k].calibration).reseeded(), record) for k in order]
    )
    runs = {k: np.array([scored[k].result.evidence, rerun.evidence]) for k, rerun in zip(order, again, strict=True)}
    best = max(order, key=lambda k: runs[k].mean())
    close = [k for k in order if k != best and bool(np.any(runs[best] - runs[k] <= margin))]
    return best, close, _sum(rerun.seconds for rerun in again)


def _refitted(
    problem: FloatProblem,
    checks: list[MetadataCheck],
    trial: PassResult,
    record: ArrivalRecord,
    calibration: Calibration,
) -> tuple[_Refit | None, Seconds]:
    """The table with the schedule of `checks`, calibrated from its `trial` pass (the search
    starting at `calibration`'s hyperparameters) and tracked with that calibration (None:
    too few confident arrivals to calibrate); the seconds spent."""
    started = time.perf_counter()
    tried = dataclasses.replace(problem, beacons=with_supported_schedule(problem.beacons, checks))
    refitted = calibrate(trial.estimate, record, tried, start=calibration.hyper)
    calibrate_s = Seconds(calibrate_s=time.perf_counter() - started)
    if refitted is None:
        return None, calibrate_s
    result = run_pass(feeding_pass(tried, refitted), record)
    return _Refit(tried, refitted, result), calibrate_s + result.seconds


def each_beside(jobs: Sequence[Callable[[], T]]) -> list[T]:
    """job() for each job, in order, the later half computed beside the earlier half where a
    core is idle (`run.forked`): each job is its own computation, the same bits."""
    half = (len(jobs) + 1) // 2
    with Forked(lambda: [job() for job in jobs[half:]], fork=len(jobs) > half) as beside:
        results = [job() for job in jobs[:half]]
        rest = beside.result()
    return results + rest


def _sum(seconds: Iterable[Seconds]) -> Seconds:
    return sum(seconds, Seconds())
