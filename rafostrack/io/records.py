"""Listening windows from per-TOA arrays: the windowing rules every arrivals reader applies.

A reader parses its format into one entry per TOA (the window's opening time, the TOA, or
NaN for a window that stored nothing; optional labels and correlation heights) and hands
them to `window_arrivals`, which applies the rules once for every format:

- exact duplicate entries (same time and TOA) are dropped;
- TOAs outside [0, window_s] are dropped;
- a window holding more than `max_signals` TOAs keeps the earliest;
- an empty entry in a window that has TOAs is ignored;
- windows opening less than window_s after the previous one, windows with no active
  beacon, and stretches of more than `USABLE_GAP_DAYS` with no usable window are warned about.

Each rule that fires adds one warning naming the file and the first entry concerned (of
kind `ARRIVAL_FILE`; windows with no active or usable beacon `GAPS`), as
the reader names its entries (`EntryNames`: a CSV line, a MATLAB TOA entry, a NetCDF
measurement). `build_record` is the front door for readers of formats other than CSV: it
checks the arrays (some window, no missing time, none before the launch) then windows them.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

from ..domain import ArrivalRecord, BeaconTable, FloatInfo, LateArrival, Window
from ..errors import InputError, WarningKind, Warnings
from .csv_table import time_text

# A stretch longer than this with no window that has an active beacon and a stored TOA is
# warned about (the track there follows the drift model only).
USABLE_GAP_DAYS = 10.0
_LIST_MAX = 5  # how many windows / stretches a warning lists before "and N more"


# A record whose windows hold a usable TOA this rarely (with at least this many windows)
# cannot give a track (`check_usable`).
MIN_HEARD_SHARE = 0.1
MIN_WINDOWS_FOR_SHARE = 20


@dataclass(frozen=True)
class EntryNames:
    """How a reader's warnings name its entries: `where(i)` names entry i ("line 12", "TOA
    entry 3"), `toa` the TOA column, `toa_field` the TOA of one entry, `entry` one entry."""

    where: Callable[[int], str]
    toa: str = "TOA"
    toa_field: str = "TOA"
    entry: str = "entry"


def csv_names(lines: NDArray[np.intp]) -> EntryNames:
    """A CSV arrival file's names: entries are rows, named by their line (header = line 1)."""
    return EntryNames(lambda i: f"line {lines[i]}", toa="toa_s", toa_field="field 'toa_s'", entry="row")


def check_after_launch(
    path: Path, info: FloatInfo, times: NDArray[np.datetime64], where: Callable[[int], str], field: str = ""
) -> None:
    """InputError naming the earliest window when it is before the float's launch (`where(i)`
    names entry i: a line, a record; `field` is put before what was expected)."""
    first = int(np.argmin(times))
    if times[first] < info.launch_time:
        raise InputError(
            f"{path}: {where(first)}: window at {time_text(times[first])} is before the float's launch_time "
            f"{time_text(info.launch_time)}; {field}expected windows at or after the launch (check launch_time in "
            "floats.csv)"
        )


def build_record(
    path: Path,
    info: FloatInfo,
    beacons: BeaconTable,
    times: NDArray[np.datetime64],
    toa_s: NDArray[np.float64],
    warnings: Warnings,
    *,
    labels: NDArray[np.object_] | None = None,
    quality: NDArray[np.float64] | None = None,
    where: Callable[[int], str] = lambda i: f"record {i + 1}",
) -> ArrivalRecord:
    """Windows of ascending TOAs from one entry per TOA (`window_arrivals`), after checking
    that there is an entry, that none lacks its time and that none is before the launch."""
    times = np.asarray(times, dtype="datetime64[ns]")
    if not len(times):
        raise InputError(f"{path}: no listening windows in the file; expected at least one")
    if np.isnat(times).any():
        raise InputError(f"{path}: {where(int(np.argmax(np.isnat(times))))}: window time missing; expected a time")
    check_after_launch(path, info, times, where)
    toa = np.asarray(toa_s, dtype=float)
    quality = None if quality is None else np.asarray(quality, dtype=float)
    return window_arrivals(path, info, beacons, times, toa, warnings, EntryNames(where), labels=labels, quality=quality)


def window_arrivals(
    path: Path,
    info: FloatInfo,
    beacons: BeaconTable,
    times: NDArray[np.datetime64],
    toa: NDArray[np.float64],
    warnings: Warnings,
    names: EntryNames,
    *,
    labels: NDArray[np.object_] | None = None,
    quality: NDArray[np.float64] | None = None,
) -> ArrivalRecord:
    """The float's windows, in time order, of ascending TOAs, by the rules of the module
    docstring. Entries sort by (time, TOA), empty TOAs last, ties in entry order; windows
    are runs of equal times; an empty label is clutter (None)."""
    duplicate, outside = _dropped_entries(path, info, times, toa, warnings, names)
    grouped = _Grouped.of(times, toa, duplicate, outside, info.max_signals)
    _warn_windows(path, info, grouped, warnings, names)
    n_stored = np.bincount(grouped.win_of_entry[grouped.stored], minlength=grouped.n_windows)
    check_usable(path, info, toa, outside, n_stored, names)
    _warn_beaconless(path, info, beacons, grouped.win_times, n_stored, warnings)
    stored = grouped.order[grouped.stored]
    splits = np.cumsum(n_stored)[:-1]
    label_tuples: list[tuple[str | None, ...] | None] = [None] * grouped.n_windows
    if labels is not None:
        label_tuples = [tuple(lab if lab else None for lab in g) for g in np.split(labels[stored], splits)]
    quality_groups: list[NDArray[np.float64] | None] = [None] * grouped.n_windows
    if quality is not None:
        quality_groups = list(np.split(quality[stored], splits))
    toa_groups = np.split(toa[stored], splits)
    windows = tuple(
        Window(time=t, toa_s=g, beacon_id=lab, quality=q)
        for t, g, lab, q in zip(grouped.win_times, toa_groups, label_tuples, quality_groups, strict=True)
    )
    return ArrivalRecord(info.float_id, Path(path), windows, late=_late(grouped, toa, info, labels, quality))


def _late(
    grouped: _Grouped, toa: NDArray, info: FloatInfo, labels: NDArray[np.object_] | None, quality: NDArray | None
) -> tuple[LateArrival, ...]:
    """The TOAs later than the window, by window and TOA (`ArrivalRecord.late`)."""
    entries = grouped.order
    late = np.flatnonzero(grouped.has_toa & (toa[entries] > info.window_s))
    return tuple(
        LateArrival(
            int(grouped.win_of_entry[j]),
            float(toa[entries[j]]),
            (labels[entries[j]] or None) if labels is not None else None,
            float(quality[entries[j]]) if quality is not None else float("nan"),
        )
        for j in late
    )


def with_longer_window(record: ArrivalRecord, window_s: float, max_signals: int) -> ArrivalRecord:
    """`record` as read with a window of `window_s` s, longer than the one it was read with:
    each window's late TOAs up to `window_s` (`ArrivalRecord.late`, all later than the
    window's own) stored after its TOAs while it holds fewer than `max_signals`."""
    taken: dict[int, list[LateArrival]] = {}
    for arrival in record.late:
        if arrival.toa_s <= window_s:
            taken.setdefault(arrival.window, []).append(arrival)
    windows = list(record.windows)
    for k, arrivals in taken.items():
        window = windows[k]
        extra = arrivals[: max_signals - window.n_signals]
        if not extra:
            continue
        labels = None if window.beacon_id is None else (*window.beacon_id, *(a.beacon_id for a in extra))
        quality = None if window.quality is None else np.concatenate([window.quality, [a.quality for a in extra]])
        toa = np.concatenate([window.toa_s, [a.toa_s for a in extra]])
        windows[k] = Window(window.time, toa, beacon_id=labels, quality=quality)
    late = tuple(a for a in record.late if a.toa_s > window_s)
    return dataclasses.replace(record, windows=tuple(windows), late=late)


def check_usable(
    path: Path, info: FloatInfo, toa: NDArray, outside: NDArray[np.bool_], n_stored: NDArray, names: EntryNames
) -> None:
    """Refuse a record that cannot give a track: no usable TOA at all, or TOAs in fewer than
    `MIN_HEARD_SHARE` of its windows (of at least `MIN_WINDOWS_FOR_SHARE`). A track from
    such a record would follow the drift model alone; the cause is most often the TOAs'
    unit, the window length or the wrong file, which the error says."""
    given = ~np.isnan(toa)
    heard = n_stored > 0
    if heard.any() and (len(heard) < MIN_WINDOWS_FOR_SHARE or heard.mean() >= MIN_HEARD_SHARE):
        return
    if not given.any():
        cause = f"every {names.toa} is empty; expected arrival times in seconds (is this the float's arrival file?)"
    elif outside[given].all() or not heard.any():
        values = toa[given]
        cause = (
            f"all {int(given.sum())} TOAs lie outside the window [0, {info.window_s:g}] s (they run from "
            f"{values.min():g} to {values.max():g}); expected seconds from the window's opening: check the unit of "
            f"{names.toa} (milliseconds?) and window_s in floats.csv"
        )
    else:
        cause = (
            f"only {int(heard.sum())} of {len(heard)} windows ({heard.mean():.0%}) hold a TOA inside the window "
            f"[0, {info.window_s:g}] s ({int(outside.sum())} TOAs outside it); at least "
            f"{MIN_HEARD_SHARE:.0%} expected: check the unit of {names.toa} and window_s in floats.csv"
        )
    raise InputError(f"{path}: no track from this record: {cause}")


def _dropped_entries(
    path: Path,
    info: FloatInfo,
    times: NDArray[np.datetime64],
    toa: NDArray[np.float64],
    warnings: Warnings,
    names: EntryNames,
) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """The entries dropped, with a warning for each rule that fires: exact duplicates (every
    repeat of an earlier (time, TOA)), and TOAs outside [0, window_s] (their window stays)."""
    duplicate = pd.DataFrame({"t": times, "toa": toa}).duplicated().to_numpy()
    if duplicate.any():
        warnings.add(
            f"{path}: {int(duplicate.sum())} duplicate {names.entry}(s) (same time and {names.toa}) dropped "
            f"(first at {names.where(int(np.argmax(duplicate)))})"
        )
    outside = ~np.isnan(toa) & ((toa < 0) | (toa > info.window_s))
    if outside.any():
        row = int(np.argmax(outside))
        n_neg = int((outside & (toa < 0)).sum())
        warnings.add(
            f"{path}: {int(outside.sum())} TOA(s) outside the window [0, {info.window_s:g}] s dropped "
            f"({n_neg} negative, {int(outside.sum()) - n_neg} beyond window_s; "
            f"first at {names.where(row)}: {names.toa_field} = {toa[row]:g})"
        )
    return duplicate, outside


@dataclass(frozen=True)
class _Grouped:
    """Entries sorted into windows. `order`: the entries but duplicates, by (time, TOA);
    `bounds`: where each window's run starts in `order` (and its end); per sorted entry its
    window, whether it has a TOA, whether that TOA is kept (inside the window) and whether
    it is stored (among the window's first `max_signals` kept TOAs)."""

    order: NDArray[np.intp]
    bounds: NDArray[np.intp]
    win_of_entry: NDArray[np.intp]
    win_times: NDArray[np.datetime64]
    has_toa: NDArray[np.bool_]
    keep: NDArray[np.bool_]
    stored: NDArray[np.bool_]

    @property
    def n_windows(self) -> int:
        return len(self.bounds) - 1

    @classmethod
    def of(
        cls,
        times: NDArray[np.datetime64],
        toa: NDArray[np.float64],
        duplicate: NDArray[np.bool_],
        outside: NDArray[np.bool_],
        max_signals: int,
    ) -> _Grouped:
        """Sort (empty TOAs last in their window) and group; rank r of a kept TOA among its
        window's kept TOAs = kept entries before it - kept entries before the window."""
        has_toa = ~np.isnan(toa)
        order = np.lexsort((np.where(has_toa, toa, np.inf), times))
        order = order[~duplicate[order]]
        t_sorted = times[order]
        bounds = np.concatenate(([0], np.flatnonzero(np.diff(t_sorted.view("int64"))) + 1, [len(order)]))
        win_of_entry = np.repeat(np.arange(len(bounds) - 1), np.diff(bounds))
        keep = has_toa[order] & ~outside[order]
        kept_before: NDArray[np.int64] = np.cumsum(keep) - keep
        rank: NDArray[np.int64] = kept_before - kept_before[bounds[:-1]][win_of_entry]
        stored = keep & (rank < max_signals)
        return cls(order, bounds, win_of_entry, t_sorted[bounds[:-1]], has_toa[order], keep, stored)


def _warn_windows(path: Path, info: FloatInfo, grouped: _Grouped, warnings: Warnings, names: EntryNames) -> None:
    """Warn about windows holding more than max_signals kept TOAs, windows with both an
    empty entry and TOAs, and windows opening less than window_s after the previous one."""
    starts = grouped.bounds[:-1]
    n_kept = np.add.reduceat(grouped.keep.astype(np.int64), starts)
    truncated = n_kept > info.max_signals
    if truncated.any():
        r = int(np.argmax(grouped.keep & ~grouped.stored))  # the first TOA left out
        warnings.add(
            f"{path}: {int(truncated.sum())} window(s) held more than max_signals={info.max_signals} TOAs; "
            f"kept the earliest (first: window {time_text(grouped.win_times[grouped.win_of_entry[r]])}, "
            f"{names.where(grouped.order[r])} left out)"
        )
    n_empty = np.add.reduceat((~grouped.has_toa).astype(np.int64), starts)
    n_toa = np.add.reduceat(grouped.has_toa.astype(np.int64), starts)
    mixed = (n_empty > 0) & (n_toa > 0)
    if mixed.any():
        w = int(np.argmax(mixed))
        warnings.add(
            f"{path}: {int(mixed.sum())} window(s) have both an empty {names.toa} {names.entry} and TOAs; the empty "
            f"{names.entry} was ignored (first: window {time_text(grouped.win_times[w])})"
        )
    close = np.flatnonzero(np.diff(grouped.win_times) / np.timedelta64(1, "s") < info.window_s)
    if len(close):
        w = int(close[0]) + 1
        warnings.add(
            f"{path}: {len(close)} window(s) open less than window_s={info.window_s:g} s after the previous one "
            f"(first: window {time_text(grouped.win_times[w])}, {names.where(grouped.order[starts[w]])}); "
            "expected one opening time per window, shared by all its TOAs"
        )


def _list_runs(times: NDArray[np.datetime64], flagged: ArrayLike) -> str:
    """Consecutive flagged windows as 'T' or 'T1 to T2 (n windows)', the first few of them."""
    idx = np.flatnonzero(flagged)
    runs = np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1)
    parts = [
        time_text(times[r[0]])
        if len(r) == 1
        else f"{time_text(times[r[0]])} to {time_text(times[r[-1]])} ({len(r)} windows)"
        for r in runs[:_LIST_MAX]
    ]
    more = f"; and {len(runs) - _LIST_MAX} more stretch(es)" if len(runs) > _LIST_MAX else ""
    return "; ".join(parts) + more


def _warn_beaconless(
    path: Path,
    info: FloatInfo,
    beacons: BeaconTable,
    win_times: NDArray[np.datetime64],
    n_stored: NDArray[np.int64],
    warnings: Warnings,
) -> None:
    """Warn about windows with no active beacon, and long stretches with no usable window."""
    t = win_times[:, None]
    active = (np.isnat(beacons.start)[None, :] | (beacons.start[None, :] <= t)) & (
        np.isnat(beacons.end)[None, :] | (t <= beacons.end[None, :])
    )
    none_active = ~active.any(axis=1)
    if none_active.any():
        warnings.add(
            f"{path}: {int(none_active.sum())} window(s) with no active beacon (beacons.csv start/end), "
            f"tracked by the drift model only: {_list_runs(win_times, none_active)}",
            kind=WarningKind.GAPS,
        )
    usable = ~none_active & (n_stored > 0)
    anchors = np.concatenate(([info.launch_time], win_times[usable], [win_times[-1]]))
    gap_days = np.diff(anchors) / np.timedelta64(1, "s") / 86400.0
    long = np.flatnonzero(gap_days > USABLE_GAP_DAYS)
    if len(long):
        parts = [
            f"{time_text(anchors[i])} to {time_text(anchors[i + 1])} ({gap_days[i]:.1f} days)" for i in long[:_LIST_MAX]
        ]
        more = f"; and {len(long) - _LIST_MAX} more" if len(long) > _LIST_MAX else ""
        warnings.add(
            f"{path}: no usable beacon (no window with an active beacon and a stored TOA) for more than "
            f"{USABLE_GAP_DAYS:g} days: {'; '.join(parts)}{more}; the track there follows the drift model only",
            kind=WarningKind.GAPS,
        )
