"""A source's schedule grossly wrong in beacons.csv (the wrong transmission slot, an offset tens
of seconds off, an active period that ends too soon): where do its signals really arrive?

The Kalman checks (`metadata_checks`) see a source only through the arrivals a pass
labelled to it; a source whose table puts its signals tens or hundreds of seconds from
where they arrive has none: its signals are labelled clutter, and it is never checked.
From a calibrated pass's track, every stored TOA of every window is compared with each
source's predicted arrival time (the calibration's timing and clock): the residuals
r = T - mu of a source's own signals pile up at one value, its offset error, while other
sources' signals (those within `EXPLAINED_S` of another active source's prediction are
left out) and clutter spread over the window. Per source, the windows with a residual
within `MATCH_S` of d are counted, N(d), over the candidate offsets d on a grid of
`MATCH_S` / 2; the best d beyond `[checks] offset_tolerance_s`, with N(d) >= `MIN_HITS`
and N(d) > 2 N(0), is the source's candidate offset (the calibrated offset plus the median
residual of its hits). Its active period likewise: hits at the (candidate) offset in
windows outside the table's period, at least `MIN_HITS` and beyond what clutter gives by
`CANDIDATE_Z` Poisson sds, make the first (last) hit a candidate start (end).

A pile can be chance (clutter, or signals of another source the track does not place
right), so a candidate is weighed by the tracker's own model: the record's log-likelihood
at the track's positions, association summed out, misses and clutter included (the
calibrated model, each source's detection as fitted: under a flat detection law, moving a
far source that is rarely heard to a late time, past what the float stores, would gain
from its misses alone), with the candidate's schedule against the calibration's,

    gain = sum_w log p(T_w | x_w, candidate) - sum_w log p(T_w | x_w, calibration),

and only candidates gaining more than `MIN_GAIN_NATS` are returned, strongest first. A
chance pile gains where it hits and loses wherever the moved source is due and not heard.
The gain holds the track fixed, and a track pulled by one wrong source makes others look
shifted: the method (`run.schedule_scan.scanned_schedules`) therefore tracks the record again
with the strongest candidates and keeps one only where the whole record's evidence rises.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from ..config import with_overrides
from ..domain import ArrivalRecord, BeaconTable, FloatInfo, Particles
from ..likelihoods import arrivals_from_config
from ..model import measurement as m
from ..problem import FloatProblem
from ..summaries.estimates import Estimate
from .metadata_checks import CONTRADICTED, MetadataCheck, beacon_source

MATCH_S = 10.0  # a TOA within this of a source's prediction matches it (track and timing errors)
EXPLAINED_S = 60.0  # a TOA this near another active source's prediction may be its signal
MIN_HITS = 10
CANDIDATE_Z = 3.0  # hits outside the table's period beyond clutter by this many Poisson sds
MIN_GAIN_NATS = 25.0  # a candidate gaining less than this along a fixed track is not tried


@dataclasses.dataclass(frozen=True)
class _Residuals:
    """One source's residuals: per window (its time, whether the table has the source
    active), the residuals of the window's TOAs (ragged: window index per residual)."""

    time: NDArray[np.datetime64]  # (W,)
    active: NDArray[np.bool_]  # (W,)
    n_toas: NDArray[np.intp]  # (W,)
    window: NDArray[np.intp]  # (R,) the window of each residual
    residual_s: NDArray[np.float64]  # (R,)


def _residuals(
    record: ArrivalRecord, track: pd.DataFrame, beacons: BeaconTable, info: FloatInfo, model: m.ModelConfig
) -> list[_Residuals]:
    """Every source's residuals over the windows the track covers (module docstring)."""
    at = track.set_index("time")
    windows = [w for w in record.windows if w.n_signals > 0 and w.time in at.index]
    rows = np.arange(len(beacons))
    times = np.array([w.time for w in windows], dtype="datetime64[ns]")
    lat = at.loc[times, "lat"].to_numpy()
    lon = at.loc[times, "lon"].to_numpy()
    mu = np.empty((len(windows), len(beacons)))
    for k, w in enumerate(windows):
        wb = m.window_beacons(beacons, info, w.time, index=rows)
        mu[k] = m.predicted_toa_s(m.beacon_ranges_m(lat[k : k + 1], lon[k : k + 1], wb), wb, model)[0]
    n_toas = np.array([w.n_signals for w in windows], dtype=np.intp)
    owner = np.repeat(np.arange(len(windows)), n_toas)
    toas = np.concatenate([w.toa_s for w in windows]) if windows else np.zeros(0)
    active = np.array([beacons.active_at(t) for t in times]).reshape(len(windows), len(beacons))
    residual = toas[:, None] - mu[owner]  # (R, B)
    explained = (np.abs(residual) <= EXPLAINED_S) & active[owner]  # by a source's table values
    found = []
    for i in range(len(beacons)):
        free = ~np.delete(explained, i, axis=1).any(axis=1)  # not another active source's signal
        found.append(_Residuals(times, active[:, i], n_toas, owner[free], residual[free, i]))
    return found


def _hits(res: _Residuals, shift_s: float, windows: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """(W,) the windows among `windows` with a residual within `MATCH_S` of `shift_s`."""
    near = np.abs(res.residual_s - shift_s) <= MATCH_S
    hit = np.zeros(len(res.time), dtype=bool)
    hit[res.window[near]] = True
    return hit & windows


def _background(res: _Residuals, windows: NDArray[np.bool_], window_s: float) -> float:
    """The expected count of windows with a clutter TOA within `MATCH_S` of any one shift."""
    p = 1.0 - (1.0 - min(2 * MATCH_S / window_s, 1.0)) ** res.n_toas[windows]
    return float(p.sum())


def _excess_z(count: int, expected: float) -> float:
    """How far `count` lies above what clutter gives, in Poisson sds."""
    return (count - expected) / float(np.sqrt(max(expected, 1.0)))


def _significant(count: int, expected: float) -> bool:
    return count >= MIN_HITS and _excess_z(count, expected) > CANDIDATE_Z


def _best_shift(res: _Residuals, window_s: float) -> tuple[float, int]:
    """The shift with the most windows matching, on a grid of `MATCH_S` / 2 over the window,
    and its count, over the windows the table has the source active: each residual votes
    once per window for the grid shifts within `MATCH_S` of it."""
    step = MATCH_S / 2
    grid = np.arange(-window_s, window_s + step, step)
    keep = res.active[res.window]
    nearest = np.rint((res.residual_s[keep] + window_s) / step).astype(np.int64)
    reach = int(MATCH_S // step)
    votes = (nearest[:, None] + np.arange(-reach, reach + 1)[None, :]).ravel()
    windows = np.repeat(res.window[keep], 2 * reach + 1)
    inside = (votes >= 0) & (votes < len(grid))
    pairs = np.unique(np.column_stack([windows[inside], votes[inside]]), axis=0)
    counts = np.bincount(pairs[:, 1], minlength=len(grid)) if len(pairs) else np.zeros(len(grid), dtype=np.int64)
    best = int(np.argmax(counts))
    return float(grid[best]), int(counts[best])


@dataclasses.dataclass(frozen=True)
class ScheduleCandidate:
    """One source's schedule as the arrivals along a track place it: the table values it
    contradicts (offset, start, end) and its log-likelihood gain (module docstring)."""

    checks: list[MetadataCheck]
    gain_nats: float


def schedule_candidates(
    table: FloatProblem, calibrated: FloatProblem, estimate: Estimate, record: ArrivalRecord
) -> list[ScheduleCandidate]:
    """Each source's candidate schedule along `estimate`'s track (module docstring), weighed
    with the `calibrated` problem (the calibration's beacon table, with its timing
    corrections and each source's fitted detection, its clock and model); the checks name
    the values of `table` (the user's). Those gaining more than `MIN_GAIN_NATS`, strongest
    first."""
    beacons, config = calibrated.beacons, calibrated.tracking_config
    window_s = calibrated.info.window_s
    found = []
    for row, res in enumerate(_residuals(record, estimate.track, beacons, calibrated.info, config.model)):
        if res.active.sum() < MIN_HITS:
            continue
        shift, count = _best_shift(res, window_s)
        at_table = int(_hits(res, 0.0, res.active).sum())
        moved = abs(shift) > config.checks.offset_tolerance_s and count >= MIN_HITS and count > 2 * at_table
        checks = []
        if moved:
            near = np.abs(res.residual_s - shift) <= MATCH_S
            supported = float(beacons.offset_s[row]) + float(np.median(res.residual_s[near]))
            checks.append(_offset_check(table.beacons, row, supported))
        checks += _period_checks(table.beacons, row, res, shift if moved else 0.0, window_s)
        if checks:
            found.append(checks)
    if not found:
        return []
    before = _record_loglik(calibrated, estimate, record)
    candidates = []
    for checks in found:
        moved_problem = dataclasses.replace(calibrated, beacons=with_supported_schedule(beacons, checks))
        gain = _record_loglik(moved_problem, estimate, record) - before
        if gain > MIN_GAIN_NATS:
            candidates.append(ScheduleCandidate(checks, round(gain, 1)))
    return sorted(candidates, key=lambda c: c.gain_nats, reverse=True)


def _record_loglik(problem: FloatProblem, estimate: Estimate, record: ArrivalRecord) -> float:
    """The record's log-likelihood at the track's positions under `problem` (the ranked model)."""
    likelihood = arrivals_from_config(
        problem.beacons, problem.info, with_overrides(problem.tracking_config, filter={"likelihood": "ranked"})
    )
    at = estimate.track.set_index("time")
    windows = [w for w in record.windows if w.time in at.index]
    times = [w.time for w in windows]
    lat, lon = at.loc[times, "lat"].to_numpy(), at.loc[times, "lon"].to_numpy()
    return float(
        sum(likelihood.evaluate(Particles(lat[k : k + 1], lon[k : k + 1]), w, marginals=False).loglik[0]
            for k, w in enumerate(windows))
    )  # fmt: skip


def _offset_check(beacons: BeaconTable, row: int, supported_s: float) -> MetadataCheck:
    file, line, name = beacon_source(beacons, row)
    given, supported = float(beacons.offset_s[row]), round(supported_s, 3)
    return MetadataCheck(file, line, name, "offset_s", given, supported, MATCH_S, "s", CONTRADICTED, used=supported)


def _period_checks(
    beacons: BeaconTable, row: int, res: _Residuals, shift_s: float, window_s: float
) -> list[MetadataCheck]:
    """The start and end against the hits at `shift_s` in the windows outside the table's
    period (module docstring)."""
    file, line, name = beacon_source(beacons, row)
    found = []
    for field, outside, pick in (
        ("start", res.time < beacons.start[row], np.min),
        ("end", res.time > beacons.end[row], np.max),
    ):
        if not outside.any():
            continue
        hits = _hits(res, shift_s, outside)
        if not _significant(int(hits.sum()), _background(res, outside, window_s)):
            continue
        given, supported = _iso(getattr(beacons, field)[row]), _iso(pick(res.time[hits]))
        found.append(
            MetadataCheck(file, line, name, field, given, supported, None, "time", CONTRADICTED, used=supported)
        )
    return found


def _iso(time: np.datetime64) -> str:
    return str(np.datetime_as_string(np.asarray(time, dtype="datetime64[s]"), unit="s")) + "Z"


def with_supported_schedule(beacons: BeaconTable, checks: list[MetadataCheck]) -> BeaconTable:
    """`beacons` with each contradicted offset, start and end replaced by the supported one."""
    offset, start, end = beacons.offset_s.copy(), beacons.start.copy(), beacons.end.copy()
    row_of = beacons.index_of()
    for check in checks:
        if check.outcome != CONTRADICTED or check.id not in row_of:
            continue
        row = row_of[check.id]
        if check.field == "offset_s" and isinstance(check.supported, float):
            offset[row] = check.supported
        elif check.field in ("start", "end") and isinstance(check.supported, str):
            (start if check.field == "start" else end)[row] = np.datetime64(check.supported.rstrip("Z"), "ns")
    return dataclasses.replace(beacons, offset_s=offset, start=start, end=end)
