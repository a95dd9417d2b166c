"""Where the method's time goes: per pass, per stage (`speed.py --profile`).

The method (`run.method.track_record`) runs passes (`Tracker.track`) and calibrations
(`calibrate.calibrate`); each call is timed on its own (wall clock, unprofiled), and profiled
on its own in a second run (cProfile). A function's own time (cProfile's tottime) counts
to the first stage found walking up its callers (`STAGES`, by the function's module and
name): numpy's and numba's calls count to the rafostrack function that made them, shared
between callers in proportion to the time each call took. Each stage's share of a call's
profiled time, times the call's unprofiled wall time, is the table's estimate of its
seconds (cProfile's own overhead falls mostly on the Python-level stages, so these lean
high and the compiled ones low).
"""

from __future__ import annotations

import cProfile
import pstats
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import pandas as pd

import rafostrack.run.method as method
import rafostrack.run.schedule_scan as schedule_scan
from rafostrack.run.one_pass import Tracker

# Stage name -> (path fragment, function names or None for all) in order: the first match wins.
STAGES: list[tuple[str, str, tuple[str, ...] | None]] = [
    ("motion", "rafostrack/motion/", None),
    ("ranges", "rafostrack/model/geodesy.py", None),
    ("prediction", "rafostrack/model/measurement.py",
     ("window_beacons", "predicted_toa_s", "detection_prob", "window_prediction", "beacon_ranges_m")),
    ("factors", "rafostrack/model/", None),
    ("association", "rafostrack/engines/", None),
    ("evidence kernel", "rafostrack/likelihoods/window_evidence.py", None),  # all of the above, compiled in one
    ("evidence", "rafostrack/likelihoods/", None),
    ("resampling", "rafostrack/filtering/resampling.py", None),
    ("modes", "rafostrack/filtering/modes.py", None),
    ("recovery", "rafostrack/filtering/recovery.py", None),
    ("filter", "rafostrack/filtering/", None),
    ("smoother", "rafostrack/smoothing/", None),
    ("summaries", "rafostrack/summaries/", None),
    ("source scan", "rafostrack/calibrate/source_scan.py", None),
    ("calibration", "rafostrack/calibrate/", None),
]  # fmt: skip

Func = tuple[str, int, str]  # cProfile's (file, line, name)


def stage_of(func: Func) -> str | None:
    """The stage a function belongs to (`STAGES`), or None."""
    path, _, name = func
    path = path.replace("\\", "/")
    for stage, fragment, names in STAGES:
        if fragment in path and (names is None or name in names):
            return stage
    return None


def stage_seconds(stats: pstats.Stats) -> dict[str, float]:
    """Profiled seconds per stage: each function's own time, to its nearest staged caller."""
    table: dict[Func, Any] = stats.stats  # type: ignore[attr-defined]
    shares: dict[Func, dict[str, float]] = {}

    def resolve(func: Func, depth: int = 0) -> dict[str, float]:
        if func in shares:
            return shares[func]
        own = stage_of(func)
        if own is not None or depth > 60 or func not in table:
            result = {own or "other": 1.0}
        else:
            callers = table[func][4]
            total = sum(edge[2] for edge in callers.values())
            result = {}
            if total <= 0:
                result = {"other": 1.0}
            for caller, edge in callers.items():
                if total <= 0:
                    break
                for stage, share in resolve(caller, depth + 1).items():
                    result[stage] = result.get(stage, 0.0) + share * edge[2] / total
        shares[func] = result
        return result

    seconds: dict[str, float] = {}
    for func, (_, _, own_time, _, _) in table.items():
        for stage, share in resolve(func).items():
            seconds[stage] = seconds.get(stage, 0.0) + share * own_time
    return seconds


@dataclass
class _Calls:
    """The method's calls in order: (what, wall seconds, profile stats or None)."""

    calls: list[tuple[str, float, pstats.Stats | None]] = field(default_factory=list)
    passes: int = 0


@contextmanager
def _recorded(profile: bool) -> Iterator[_Calls]:
    """Wrap `Tracker.track` and the method's and source scan's `calibrate` so that each call
    is timed (and profiled when `profile`); the originals are put back on exit."""
    record = _Calls()
    track, calibrate = Tracker.track, method.calibrate

    def wrapped(name: Callable[[], str], call: Callable[..., Any]) -> Callable[..., Any]:
        def run(*args: Any, **kwargs: Any) -> Any:
            profiler = cProfile.Profile() if profile else None
            started = time.perf_counter()
            if profiler:
                profiler.enable()
            try:
                return call(*args, **kwargs)
            finally:
                if profiler:
                    profiler.disable()
                elapsed = time.perf_counter() - started
                record.calls.append((name(), elapsed, pstats.Stats(profiler) if profiler else None))

        return run

    def pass_name() -> str:
        record.passes += 1
        return f"pass {record.passes}"

    Tracker.track = wrapped(pass_name, track)  # type: ignore[method-assign]
    for module in (method, schedule_scan):
        module.calibrate = wrapped(lambda: "calibration", calibrate)  # type: ignore[attr-defined]
    try:
        yield record
    finally:
        Tracker.track = track  # type: ignore[method-assign]
        for module in (method, schedule_scan):
            module.calibrate = calibrate  # type: ignore[attr-defined]


def stage_table(run: Callable[[], Any]) -> pd.DataFrame:
    """Run the method twice (timed, then profiled) and tabulate seconds per call and stage:
    rows are the calls in order (passes, and calibrations, a scan's trial passes among
    them), columns the stages, then the call's wall seconds."""
    with _recorded(profile=False) as timed:
        run()
    with _recorded(profile=True) as profiled:
        run()
    rows = []
    for (name, wall, _), (_, _, stats) in zip(timed.calls, profiled.calls, strict=True):
        assert stats is not None
        seconds = stage_seconds(stats)
        total = sum(seconds.values())
        rows.append({"call": name, **{k: wall * v / total for k, v in seconds.items()}, "wall_s": wall})
    table = pd.DataFrame(rows).fillna(0.0)
    order = [s for s, _, _ in STAGES] + ["other"]
    stages = [s for s in order if s in table.columns and table[s].sum() >= 0.005]
    table = table[["call", *stages, "wall_s"]]
    total = table.drop(columns="call").sum().to_frame().T.assign(call="all")
    return pd.concat([table, total[table.columns]], ignore_index=True)
