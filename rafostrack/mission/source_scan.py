"""Sources the floats hardly labelled, looked for on every float at once: a gross error in
a source's table values (an offset tens of seconds off, another source's slot) makes its
signals arrive where no float expects them, so they are stored but labelled clutter, and
the array fit, which rests on labels, never sees the source.

For such a source (confident labels on fewer than `SCAN_BELOW_SHARE` of the mission's
windows), every stored TOA the floats did not label confidently is compared with the
source's predicted arrival along each float's track, with the tables as given:
r = toa - (offset + drift t + clock(t) + range / c). Clutter falls evenly over the
listening window, so its r spread evenly over +-`MAX_SHIFT_S`; the source's own signals, if
its table is Delta off, pile up at r = Delta, within the TOA noise and the track's error. A
window of r of width 2 `HALF_WIDTH_S` holding k of the n residuals, where clutter alone
would put lambda = n 2 w / (2 `MAX_SHIFT_S`), is a pile when its Poisson tail probability
P(K >= k; lambda), times the number of windows and sources scanned, is below `ALPHA`
(piles within 3 w of 0 are the source's ordinary misses and not a shift). The pile's TOAs
are then labelled as the source's, for the array fit to judge and estimate its offset as
any other value; the fit, not the scan, names it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd
from numpy.typing import NDArray
from scipy.stats import poisson

from ..calibrate.timing_problem import CONFIDENT_PROB
from ..domain import elapsed_days
from ..model.geodesy import range_m
from ..problem import FloatProblem
from ..summaries.estimates import Estimate

MAX_SHIFT_S = 300.0
HALF_WIDTH_S = 4.0
ALPHA = 1e-6
SCAN_BELOW_SHARE = 0.05
MIN_PILE = 8


@dataclass(frozen=True)
class Pile:
    """A source's unlabelled arrivals piled up `shift_s` from its table's prediction."""

    row: int  # beacon-table row
    shift_s: float
    count: int
    expected: float  # what clutter alone would put in the pile's window
    floats: int


def loose_residuals(estimate: Estimate, problem: FloatProblem, row: int) -> pd.Series:
    """The float's TOAs not labelled confidently, minus the source's predicted arrivals at
    the float's track (s), indexed as the labels."""
    labels = estimate.labels
    loose = labels[labels["beacon_id"].isna() | (labels["prob"] < CONFIDENT_PROB)]
    at = estimate.track.set_index("time").reindex(loose["time"])
    times = loose["time"].to_numpy(dtype="datetime64[ns]")
    beacons, info = problem.beacons, problem.info
    epoch = info.launch_time if np.isnat(beacons.start[row]) else beacons.start[row]
    ranges = range_m(at["lat"].to_numpy(), at["lon"].to_numpy(), beacons.lat[row], beacons.lon[row])
    predicted = (
        beacons.offset_s[row]
        + beacons.drift_s_per_day[row] * elapsed_days(times, epoch)
        + info.clock_offset_s(times)
        + ranges / problem.config.model.sound_speed_m_s
    )
    return pd.Series(loose["toa_s"].to_numpy(dtype=float) - predicted, index=loose.index)


def _scanned(r: pd.Series) -> NDArray[np.float64]:
    values = r.to_numpy()
    return values[np.isfinite(values) & (np.abs(values) <= MAX_SHIFT_S)]


def _pile(r_by_float: list[NDArray], tests: int) -> tuple[float, int, float, int] | None:
    """The densest window of the residuals, when it is a pile (module docstring)."""
    r = np.sort(np.concatenate(r_by_float))
    if len(r) < MIN_PILE:
        return None
    ends = np.searchsorted(r, r + 2 * HALF_WIDTH_S, side="right")
    counts = ends - np.arange(len(r))
    centres = r + HALF_WIDTH_S
    counts = np.where(np.abs(centres) > 3 * HALF_WIDTH_S, counts, 0)
    best = int(np.argmax(counts))
    k, expected = int(counts[best]), len(r) * HALF_WIDTH_S / MAX_SHIFT_S
    if k < MIN_PILE or poisson.sf(k - 1, expected) * tests > ALPHA:
        return None
    shift = float(np.mean(r[best : ends[best]]))
    floats = sum(bool(np.any(np.abs(x - shift) <= HALF_WIDTH_S)) for x in r_by_float)
    return shift, k, expected, floats


def scan_sources(tracked: Sequence[tuple[Estimate, FloatProblem]]) -> list[Pile]:
    """The piles of the sources the floats hardly labelled (module docstring)."""
    if not tracked:
        return []
    beacons = tracked[0][1].beacons
    windows = sum(e.track["time"].nunique() for e, _ in tracked)
    labelled = pd.concat([e.labels[e.labels["prob"] >= CONFIDENT_PROB]["beacon_id"] for e, _ in tracked])
    counts = labelled.value_counts()
    scanned = [row for row, b in enumerate(beacons.beacon_id) if counts.get(b, 0) < SCAN_BELOW_SHARE * windows]
    tests = max(1, len(scanned)) * int(MAX_SHIFT_S / HALF_WIDTH_S)
    piles = []
    for row in scanned:
        found = _pile([_scanned(loose_residuals(e, p, row)) for e, p in tracked], tests)
        if found is not None:
            piles.append(Pile(row, *found))
    return piles


def relabelled(estimate: Estimate, problem: FloatProblem, piles: Sequence[Pile]) -> Estimate:
    """The estimate with each pile's unlabelled TOAs (within `HALF_WIDTH_S` of the source's
    prediction shifted by the pile's shift) labelled as its source's, at probability 1."""
    labels = estimate.labels.copy()
    for pile in piles:
        r = loose_residuals(Estimate(estimate.kind, estimate.track, labels, estimate.modes), problem, pile.row)
        hits = r.index[(r - pile.shift_s).abs().to_numpy() <= HALF_WIDTH_S]
        labels.loc[hits, "beacon_id"] = str(problem.beacons.beacon_id[pile.row])
        labels.loc[hits, "prob"] = 1.0
    return Estimate(estimate.kind, estimate.track, labels, estimate.modes)
