"""The CSV mission format: `beacons.csv`, `floats.csv` and one arrival file per float.

Every problem a user can fix raises `InputError` with the file, the line (as a text editor
counts them, header = line 1) and the field; recoverable oddities are recorded in a
`Warnings` list.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from ..config import ModelConfig
from ..domain import ArrivalRecord, BeaconTable, FloatInfo
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
from .records import check_after_launch, csv_names, window_arrivals

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
        source_file=str(path),
        source_line=np.array([line_of(frame, row) for row in range(len(frame))], dtype=np.int64),
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
            clock_offset_end_s=float(clock1[row]),
            window_s=float(window[row]),
            max_signals=int(max_sig[row]),
            depth_m=float(depth[row]),
            source=(str(path), line_of(frame, row)),
        )
    return floats


# --------------------------------------------------------------------------------------
# <float_id>.csv


@dataclass(frozen=True)
class _ArrivalRows:
    """An arrival file's rows as parsed: per row its line, window time, TOA (NaN = empty),
    and the optional quality and beacon_id columns (None when absent)."""

    lines: NDArray[np.intp]
    times: NDArray[np.datetime64]
    toa_s: NDArray[np.float64]
    quality: NDArray[np.float64] | None
    labels: NDArray[np.object_] | None


def read_arrivals(path: Path, info: FloatInfo, beacons: BeaconTable, warnings: Warnings) -> ArrivalRecord:
    """Read one float's arrival file into windows of ascending TOAs.

    Rows may come in any order. An empty `toa_s` marks a window in which nothing was
    stored. The rows are parsed, validated (known beacon labels, no window before the
    launch), then windowed by the rules every reader shares (`records.window_arrivals`):
    exact duplicate rows are dropped, TOAs outside [0, window_s] are dropped, and a window
    holding more than `max_signals` TOAs keeps the earliest, each with a warning; windows
    with no active beacon, and stretches of more than `records.USABLE_GAP_DAYS` with no window that
    has an active beacon and a stored TOA, are warned about too.
    """
    path = Path(path)
    rows = _parse_arrivals(path)
    _validate_arrivals(path, info, beacons, rows)
    return window_arrivals(
        path,
        info,
        beacons,
        rows.times,
        rows.toa_s,
        warnings,
        csv_names(rows.lines),
        labels=rows.labels,
        quality=rows.quality,
    )


def _parse_arrivals(path: Path) -> _ArrivalRows:
    """The file's rows: time (required in every row), toa_s [, quality, beacon_id]."""
    frame = read_csv_table(path, ("time", "toa_s"), ("quality", "beacon_id"))
    if frame.empty:
        raise header_only(path, frame, "row (time, toa_s)")
    require_present(path, frame, "time", "the window's opening time (ISO-8601)")
    return _ArrivalRows(
        lines=frame.index.to_numpy(),
        times=parse_time_column(path, frame, "time"),
        toa_s=parse_float_column(path, frame, "toa_s"),
        quality=parse_float_column(path, frame, "quality") if "quality" in frame.columns else None,
        labels=frame["beacon_id"].to_numpy(dtype=object) if "beacon_id" in frame.columns else None,
    )


def _validate_arrivals(path: Path, info: FloatInfo, beacons: BeaconTable, rows: _ArrivalRows) -> None:
    """InputError for a beacon_id that is neither empty (clutter) nor in the beacon table,
    or a window before the float's launch."""
    if rows.labels is not None:
        known = [str(b) for b in beacons.beacon_id]
        unknown = (rows.labels != "") & ~pd.Series(rows.labels).isin(known).to_numpy()
        if unknown.any():
            row = int(np.argmax(unknown))
            lab = str(rows.labels[row])
            hint = nearest(lab, known) or " (expected a beacon_id of the beacons table or empty for clutter)"
            raise InputError(f"{path}: line {rows.lines[row]}: field 'beacon_id': unknown beacon {lab!r}{hint}")
    check_after_launch(path, info, rows.times, lambda i: f"line {rows.lines[i]}", field="field 'time': ")
