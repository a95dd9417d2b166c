"""The CSV mission format: `beacons.csv`, `floats.csv` and one arrival file per float.

Every problem a user can fix raises `InputError` with the file, the line (as a text editor
counts them, header = line 1) and the field; recoverable oddities are recorded in a
`Warnings` list.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

from ..config import ModelConfig
from ..domain import ArrivalRecord, BeaconTable, FloatInfo, Window
from ..errors import InputError, Warnings, nearest
from .csv_table import (
    first_duplicate,
    header_only,
    line_of,
    parse_float_column,
    parse_time_column,
    read_csv_table,
    require_present,
    time_text,
)
from .records import check_after_launch

# A stretch longer than this with no window that has an active beacon and a stored TOA is
# warned about (the track there follows the drift model only).
USABLE_GAP_DAYS = 10.0
_LIST_MAX = 5  # how many windows / stretches a warning lists before "and N more"

# --------------------------------------------------------------------------------------
# beacons.csv


def read_beacons(path: Path) -> BeaconTable:
    """Read `beacons.csv`: beacon_id, lat, lon [, offset_s, start, end, drift_s_per_day]."""
    path = Path(path)
    frame = read_csv_table(path, ("beacon_id", "lat", "lon"), ("offset_s", "start", "end", "drift_s_per_day"))
    if frame.empty:
        raise header_only(path, frame, "beacon")
    require_present(path, frame, "beacon_id", "a text id")
    first_duplicate(path, frame, "beacon_id")
    lat = parse_float_column(path, frame, "lat", lo=-90, hi=90)
    lon = parse_float_column(path, frame, "lon", lo=-180, hi=360)
    for col in ("lat", "lon"):
        require_present(path, frame, col, "a position in degrees")
    offset = parse_float_column(path, frame, "offset_s", default=0.0)
    drift = parse_float_column(path, frame, "drift_s_per_day", default=0.0)
    start = parse_time_column(path, frame, "start")
    end = parse_time_column(path, frame, "end")
    inverted = ~np.isnat(start) & ~np.isnat(end) & (end < start)
    if inverted.any():
        row = int(np.argmax(inverted))
        raise InputError(
            f"{path}: line {line_of(frame, row)}: field 'end': {time_text(end[row])} is before 'start' "
            f"{time_text(start[row])}; expected end >= start (or empty)"
        )
    return BeaconTable(
        beacon_id=frame["beacon_id"].to_numpy(dtype=object),
        lat=lat,
        lon=lon,
        offset_s=offset,
        drift_s_per_day=drift,
        start=start,
        end=end,
    )


# --------------------------------------------------------------------------------------
# floats.csv

FLOAT_REQUIRED = ("float_id", "launch_time", "launch_lat", "launch_lon")
FLOAT_OPTIONAL = (
    "end_time",
    "end_lat",
    "end_lon",
    "clock_offset_start_s",
    "clock_offset_end_s",
    "window_s",
    "max_signals",
    "depth_m",
)


def read_floats(path: Path, model: ModelConfig) -> dict[str, FloatInfo]:
    """Read `floats.csv`; missing window_s / max_signals take the config's values."""
    path = Path(path)
    frame = read_csv_table(path, FLOAT_REQUIRED, FLOAT_OPTIONAL)
    if frame.empty:
        raise header_only(path, frame, "float")
    require_present(path, frame, "float_id", "the arrival file's name, e.g. float767")
    first_duplicate(path, frame, "float_id")
    require_present(path, frame, "launch_time", "an ISO-8601 time")
    launch_time = parse_time_column(path, frame, "launch_time")
    end_time = parse_time_column(path, frame, "end_time")
    launch_lat = parse_float_column(path, frame, "launch_lat", lo=-90, hi=90)
    launch_lon = parse_float_column(path, frame, "launch_lon", lo=-180, hi=360)
    for col in ("launch_lat", "launch_lon"):
        require_present(path, frame, col, "a position in degrees")
    end_lat = parse_float_column(path, frame, "end_lat", lo=-90, hi=90)
    end_lon = parse_float_column(path, frame, "end_lon", lo=-180, hi=360)
    clock0 = parse_float_column(path, frame, "clock_offset_start_s", default=0.0)
    clock1 = parse_float_column(path, frame, "clock_offset_end_s")
    window = parse_float_column(path, frame, "window_s", default=model.window_s, lo=1e-9, expect="> 0")
    max_sig = parse_float_column(path, frame, "max_signals", default=model.max_signals, lo=1, hi=1e6)
    depth = parse_float_column(path, frame, "depth_m", lo=0, hi=11000, expect="in [0, 11000] (metres)")
    for row in np.flatnonzero(max_sig != np.round(max_sig))[:1]:
        raise InputError(
            f"{path}: line {line_of(frame, row)}: field 'max_signals': expected a whole number >= 1, "
            f"got {frame['max_signals'].iloc[row]!r}"
        )
    for row in np.flatnonzero(np.isnan(end_lat) != np.isnan(end_lon))[:1]:
        col = "end_lon" if np.isnan(end_lon[row]) else "end_lat"
        raise InputError(
            f"{path}: line {line_of(frame, row)}: field {col!r} is empty; expected both end_lat and end_lon, or neither"
        )
    for row in np.flatnonzero(~np.isnan(end_lat) & np.isnat(end_time))[:1]:
        raise InputError(
            f"{path}: line {line_of(frame, row)}: field 'end_time' is empty; expected the time of the end fix "
            "given by end_lat, end_lon"
        )
    for row in np.flatnonzero(~np.isnat(end_time) & (end_time <= launch_time))[:1]:
        raise InputError(
            f"{path}: line {line_of(frame, row)}: field 'end_time': {time_text(end_time[row])} is not after "
            f"launch_time {time_text(launch_time[row])}; expected a later time (or empty)"
        )
    floats = {}
    for row, fid in enumerate(frame["float_id"]):
        floats[fid] = FloatInfo(
            float_id=fid,
            launch_time=launch_time[row],
            launch_lat=float(launch_lat[row]),
            launch_lon=float(launch_lon[row]),
            end_time=end_time[row],
            end_lat=float(end_lat[row]),
            end_lon=float(end_lon[row]),
            clock_offset_start_s=float(clock0[row]),
            clock_offset_end_s=float(clock0[row] if np.isnan(clock1[row]) else clock1[row]),
            window_s=float(window[row]),
            max_signals=int(max_sig[row]),
            depth_m=float(depth[row]),
        )
    return floats


# --------------------------------------------------------------------------------------
# <float_id>.csv


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


def read_arrivals(path: Path, info: FloatInfo, beacons: BeaconTable, warnings: Warnings) -> ArrivalRecord:
    """Read one float's arrival file into windows of ascending TOAs.

    Rows may come in any order. An empty `toa_s` marks a window in which nothing was
    stored. Exact duplicate rows are dropped, TOAs outside [0, window_s] are dropped, and a
    window holding more than `max_signals` TOAs keeps the earliest: each with a warning.
    Windows with no active beacon, and stretches of more than `USABLE_GAP_DAYS` with no
    window that has an active beacon and a stored TOA, are warned about too.
    """
    path = Path(path)
    frame = read_csv_table(path, ("time", "toa_s"), ("quality", "beacon_id"))
    if frame.empty:
        raise header_only(path, frame, "row (time, toa_s)")
    require_present(path, frame, "time", "the window's opening time (ISO-8601)")
    times = parse_time_column(path, frame, "time")
    toa = parse_float_column(path, frame, "toa_s")
    quality = parse_float_column(path, frame, "quality") if "quality" in frame.columns else None
    lines = frame.index.to_numpy()
    labelled = "beacon_id" in frame.columns
    labels = frame["beacon_id"].to_numpy(dtype=object) if labelled else None
    if labelled:
        known = [str(b) for b in beacons.beacon_id]
        unknown = ((frame["beacon_id"] != "") & ~frame["beacon_id"].isin(known)).to_numpy()
        if unknown.any():
            row = int(np.argmax(unknown))
            lab = str(frame["beacon_id"].iloc[row])
            hint = nearest(lab, known) or " (expected a beacon_id of the beacons table or empty for clutter)"
            raise InputError(f"{path}: line {lines[row]}: field 'beacon_id': unknown beacon {lab!r}{hint}")
    check_after_launch(path, info, times, lambda i: f"line {lines[i]}", field="field 'time': ")

    dup = pd.DataFrame({"t": times, "toa": toa}).duplicated().to_numpy()
    if dup.any():
        warnings.add(
            f"{path}: {int(dup.sum())} duplicate row(s) (same time and toa_s) dropped "
            f"(first at line {lines[np.argmax(dup)]})"
        )
    has_toa = ~np.isnan(toa)
    outside = has_toa & ((toa < 0) | (toa > info.window_s))
    if outside.any():
        row = int(np.argmax(outside))
        n_neg = int((outside & (toa < 0)).sum())
        warnings.add(
            f"{path}: {int(outside.sum())} TOA(s) outside the window [0, {info.window_s:g}] s dropped "
            f"({n_neg} negative, {int(outside.sum()) - n_neg} beyond window_s; "
            f"first at line {lines[row]}: field 'toa_s' = {toa[row]:g})"
        )

    # Sort by window, then TOA (empty TOAs last), dropping duplicates; windows are runs of
    # equal times. Within a window, the kept TOAs beyond max_signals are truncated.
    order = np.lexsort((np.where(has_toa, toa, np.inf), times))
    order = order[~dup[order]]
    t_sorted = times[order]
    bounds = np.concatenate(([0], np.flatnonzero(np.diff(t_sorted.view("int64"))) + 1, [len(order)]))
    n_win = len(bounds) - 1
    win_of_row = np.repeat(np.arange(n_win), np.diff(bounds))
    win_times = t_sorted[bounds[:-1]]
    keep = has_toa[order] & ~outside[order]
    kept_before = np.cumsum(keep) - keep
    rank = kept_before - kept_before[bounds[:-1]][win_of_row]
    stored = keep & (rank < info.max_signals)
    n_kept = np.add.reduceat(keep.astype(np.int64), bounds[:-1])
    n_empty_rows = np.add.reduceat((~has_toa[order]).astype(np.int64), bounds[:-1])
    n_toa_rows = np.add.reduceat(has_toa[order].astype(np.int64), bounds[:-1])

    truncated = n_kept > info.max_signals
    if truncated.any():
        r = int(np.argmax(keep & ~stored))  # the first TOA left out
        warnings.add(
            f"{path}: {int(truncated.sum())} window(s) held more than max_signals={info.max_signals} TOAs; "
            f"kept the earliest (first: window {time_text(t_sorted[r])}, line {lines[order[r]]} left out)"
        )
    mixed = (n_empty_rows > 0) & (n_toa_rows > 0)
    if mixed.any():
        w = int(np.argmax(mixed))
        warnings.add(
            f"{path}: {int(mixed.sum())} window(s) have both an empty toa_s row and TOAs; the empty row was "
            f"ignored (first: window {time_text(win_times[w])})"
        )
    close = np.flatnonzero(np.diff(win_times) / np.timedelta64(1, "s") < info.window_s)
    if len(close):
        w = int(close[0]) + 1
        warnings.add(
            f"{path}: {len(close)} window(s) open less than window_s={info.window_s:g} s after the previous one "
            f"(first: window {time_text(win_times[w])}, line {lines[order[bounds[w]]]}); expected one "
            "opening time per window, shared by all its TOAs"
        )

    n_stored = np.bincount(win_of_row[stored], minlength=n_win)
    _warn_beaconless(path, info, beacons, win_times, n_stored, warnings)

    toa_stored = toa[order][stored]
    splits = np.cumsum(n_stored)[:-1]
    toa_groups = np.split(toa_stored, splits)
    label_tuples: list[tuple[str | None, ...] | None] = [None] * n_win
    if labels is not None:
        lab_groups = np.split(labels[order][stored], splits)
        label_tuples = [tuple(lab if lab else None for lab in g) for g in lab_groups]
    quality_groups: list[NDArray[np.float64] | None] = [None] * n_win
    if quality is not None:
        quality_groups = list(np.split(quality[order][stored], splits))
    windows = tuple(
        Window(time=t, toa_s=g, beacon_id=lab, quality=q)
        for t, g, lab, q in zip(win_times, toa_groups, label_tuples, quality_groups, strict=True)
    )
    return ArrivalRecord(float_id=info.float_id, path=path, windows=windows)


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
            f"tracked by the drift model only: {_list_runs(win_times, none_active)}"
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
            f"{USABLE_GAP_DAYS:g} days: {'; '.join(parts)}{more}; the track there follows the drift model only"
        )
