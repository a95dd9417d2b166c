"""A source's schedule grossly wrong in beacons.csv (the wrong transmission slot, an offset tens
of seconds off, an active period that ends too soon): where do its signals really arrive?

The Kalman checks (`metadata_checks`) see a source only through the arrivals a pass
labelled to it; a source whose table puts its signals tens or hundreds of seconds from
where they arrive has none: its signals are labelled clutter, and it is never checked.
From a pass's track, every stored TOA of every window is compared with each source's
predicted arrival time (table values, the calibrated clock): the residuals r = T - mu of a
source's own signals pile up at one value, its offset error, while other sources' signals
and clutter spread over the window. Per source, the windows with a residual within
`MATCH_S` of d are counted, N(d), over the candidate offsets d on a grid of `MATCH_S` / 2;
against the count clutter alone gives, E = sum over windows of 1 - (1 - 2 MATCH_S / window_s)^n_w,

    the offset is contradicted where the best d lies beyond `[checks] offset_tolerance_s`,
    N(d) >= `MIN_HITS`, (N(d) - E) / sqrt(E) > `[checks] z_score` and N(d) > 2 N(0);

the supported offset is the table's plus the median residual of its hits. Its active
period likewise: hits at the (supported) offset in windows outside the table's period,
beyond clutter by `z_score` and at least `MIN_HITS`, contradict the start (or end), and the
first (last) hit is the supported one. A shift that most heard sources share is the clock's
(calibration's to estimate), not theirs: then nothing is contradicted.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from ..domain import ArrivalRecord, BeaconTable, FloatInfo
from ..model import measurement as m
from ..problem import FloatProblem
from ..summaries.estimates import Estimate
from .metadata_checks import CONTRADICTED, MetadataCheck, beacon_source

MATCH_S = 10.0  # a TOA within this of a source's prediction matches it (track and timing errors)
EXPLAINED_S = 60.0  # a TOA this near another active source's prediction may be its signal
MIN_HITS = 10
SHARED_FRACTION = 0.5  # a shift found on more than this share of the scanned sources is the clock's
MAX_FINDINGS = 4  # sources corrected at most (`source_scan`)


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


def _significant(count: int, expected: float, z: float) -> bool:
    return count >= MIN_HITS and _excess_z(count, expected) > z


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


def source_scan(
    problem: FloatProblem, estimate: Estimate, record: ArrivalRecord, clock: FloatInfo
) -> list[MetadataCheck]:
    """Each source's offset and active period from where its signals arrive along
    `estimate`'s track (module docstring); `clock` the float's description with its
    calibrated clock. One finding at a time, the strongest first, the table corrected and
    scanned again (another source's wrongly placed signals are free TOAs, and a second
    source may find a chance alignment with them until the first is put right); only
    contradicted values are returned."""
    beacons = problem.beacons
    found: list[MetadataCheck] = []
    for _ in range(MAX_FINDINGS):
        candidates = _scan_once(problem, beacons, estimate, record, clock)
        if not candidates:
            break
        best = max(candidates, key=lambda c: c[0])[1]
        found += best
        beacons = with_supported_schedule(beacons, best)
    shifted = [c for c in found if c.field == "offset_s"]
    if shifted and len(shifted) > SHARED_FRACTION * max(1, _scanned(problem.beacons, record)):
        return [c for c in found if c.field != "offset_s"]  # the clock's, not the sources'
    return found


def _scan_once(
    problem: FloatProblem, beacons: BeaconTable, estimate: Estimate, record: ArrivalRecord, clock: FloatInfo
) -> list[tuple[float, list[MetadataCheck]]]:
    """Every source's findings under `beacons`, each source's with its strength (z)."""
    info, config = problem.info, problem.config
    z, window_s = config.checks.z_score, info.window_s
    candidates = []
    for row, res in enumerate(_residuals(record, estimate.track, beacons, clock, config.model)):
        if res.active.sum() < MIN_HITS:
            continue
        shift, count = _best_shift(res, window_s)
        at_table = int(_hits(res, 0.0, res.active).sum())
        expected = _background(res, res.active, window_s)
        moved = (
            abs(shift) > config.checks.offset_tolerance_s and _significant(count, expected, z) and count > 2 * at_table
        )
        findings = []
        if moved:
            near = np.abs(res.residual_s - shift) <= MATCH_S
            findings.append(_offset_check(beacons, row, float(np.median(res.residual_s[near]))))
        period_strength, periods = _period_checks(beacons, row, res, shift if moved else 0.0, window_s, z)
        if findings or periods:
            strength = _excess_z(count, expected) if moved else 0.0
            candidates.append((max(strength, period_strength), findings + periods))
    return candidates


def _scanned(beacons: BeaconTable, record: ArrivalRecord) -> int:
    """How many sources are active in at least `MIN_HITS` windows with TOAs."""
    times = [w.time for w in record.windows if w.n_signals > 0]
    return int(sum(np.sum([beacons.active_at(t)[i] for t in times]) >= MIN_HITS for i in range(len(beacons))))


def _offset_check(beacons: BeaconTable, row: int, shift_s: float) -> MetadataCheck:
    file, line, name = beacon_source(beacons, row)
    given = float(beacons.offset_s[row])
    return MetadataCheck(file, line, name, "offset_s", given, round(given + shift_s, 3), MATCH_S, "s", CONTRADICTED,
                         used=round(given + shift_s, 3))  # fmt: skip


def _period_checks(
    beacons: BeaconTable, row: int, res: _Residuals, shift_s: float, window_s: float, z: float
) -> tuple[float, list[MetadataCheck]]:
    """The start and end against the hits at `shift_s` in the windows outside the table's
    period; the findings and the strongest one's z."""
    file, line, name = beacon_source(beacons, row)
    found, strongest = [], 0.0
    for field, outside, pick in (
        ("start", res.time < beacons.start[row], np.min),
        ("end", res.time > beacons.end[row], np.max),
    ):
        if not outside.any():
            continue
        hits = _hits(res, shift_s, outside)
        expected = _background(res, outside, window_s)
        if not _significant(int(hits.sum()), expected, z):
            continue
        strongest = max(strongest, _excess_z(int(hits.sum()), expected))
        given, supported = _iso(getattr(beacons, field)[row]), _iso(pick(res.time[hits]))
        found.append(
            MetadataCheck(file, line, name, field, given, supported, None, "time", CONTRADICTED, used=supported)
        )
    return strongest, found


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
