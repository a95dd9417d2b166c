"""Read and validate a mission: `beacons.csv`, `floats.csv` and one arrival file per float.

Every problem a user can fix raises `InputError` with the file, the line (as a text editor
counts them, header = line 1) and the field; recoverable oddities are recorded in a
`Warnings` list. Times are ISO-8601; a time without a zone is taken as UTC. All times are
held as UTC `numpy.datetime64[ns]`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from .config import ModelConfig
from .errors import InputError, Warnings, nearest

NaT = np.datetime64("NaT", "ns")


@dataclass(frozen=True)
class BeaconTable:
    """Moored sound sources: position, transmission offset, clock drift, active period."""

    beacon_id: NDArray[np.object_]
    lat: NDArray[np.float64]
    lon: NDArray[np.float64]
    offset_s: NDArray[np.float64]
    drift_s_per_day: NDArray[np.float64]
    start: NDArray[np.datetime64]
    end: NDArray[np.datetime64]

    def __len__(self) -> int:
        return len(self.beacon_id)

    def active_at(self, time: np.datetime64) -> NDArray[np.bool_]:
        """Which beacons transmit at `time` (an empty start or end is open)."""
        after_start = np.isnat(self.start) | (self.start <= time)
        before_end = np.isnat(self.end) | (time <= self.end)
        return after_start & before_end

    def index_of(self) -> dict[str, int]:
        return {b: i for i, b in enumerate(self.beacon_id)}


@dataclass(frozen=True)
class FloatInfo:
    """One float's launch (and optional end) fix, clock offsets and storage limits."""

    float_id: str
    launch_time: np.datetime64
    launch_lat: float
    launch_lon: float
    end_time: np.datetime64
    end_lat: float
    end_lon: float
    clock_offset_start_s: float
    clock_offset_end_s: float
    window_s: float
    max_signals: int

    def clock_offset_s(self, time: NDArray[np.datetime64] | np.datetime64) -> NDArray[np.float64]:
        """Float clock error (float clock minus true time), linear from launch to end."""
        if np.isnat(self.end_time) or self.end_time <= self.launch_time:
            return np.full(np.shape(time), self.clock_offset_start_s)
        frac = (time - self.launch_time) / (self.end_time - self.launch_time)
        return self.clock_offset_start_s + frac * (self.clock_offset_end_s - self.clock_offset_start_s)

    @property
    def has_end_fix(self) -> bool:
        return not (np.isnat(self.end_time) or np.isnan(self.end_lat) or np.isnan(self.end_lon))


@dataclass(frozen=True)
class Window:
    """One listening window: its opening time and the stored arrival times, ascending."""

    time: np.datetime64
    toa_s: NDArray[np.float64]
    beacon_id: tuple[str | None, ...] | None = None  # known labels (None entry = clutter)

    @property
    def n_signals(self) -> int:
        return len(self.toa_s)


@dataclass(frozen=True)
class ArrivalRecord:
    float_id: str
    path: Path
    windows: tuple[Window, ...]

    @property
    def has_labels(self) -> bool:
        return bool(self.windows) and self.windows[0].beacon_id is not None


# --------------------------------------------------------------------------------------
# CSV helpers


def read_csv_table(path: Path, required: tuple[str, ...], optional: tuple[str, ...]) -> pd.DataFrame:
    """Read a CSV as text columns; check the header. Row i of the frame is file line i+2."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: file not found")
    try:
        frame = pd.read_csv(path, dtype=str, keep_default_na=False, encoding="utf-8-sig", skipinitialspace=True)
    except pd.errors.EmptyDataError:
        raise InputError(f"{path}: file is empty (expected a header line: {', '.join(required)})") from None
    except (pd.errors.ParserError, UnicodeDecodeError, OSError) as exc:
        reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise InputError(f"{path}: cannot parse as CSV: {reason}") from None
    frame.columns = [str(c).strip() for c in frame.columns]
    if len(frame.columns) == 1 and ";" in frame.columns[0]:
        raise InputError(f"{path}: line 1: columns are separated by ';'; expected ',' (comma-separated CSV)")
    known = set(required) | set(optional)
    for col in required:
        if col not in frame.columns:
            raise InputError(f"{path}: line 1: missing required column {col!r}{nearest(col, frame.columns)}")
    for col in frame.columns:
        if col not in known:
            raise InputError(f"{path}: line 1: unknown column {col!r}{nearest(col, known)}")
    if frame.columns.duplicated().any():
        raise InputError(f"{path}: line 1: duplicated column names")
    return frame.apply(lambda c: c.str.strip())


def _line(row: int) -> int:
    return row + 2


def parse_float_column(
    path: Path,
    frame: pd.DataFrame,
    col: str,
    *,
    default: float | None = None,
    lo: float = -np.inf,
    hi: float = np.inf,
) -> NDArray[np.float64]:
    """Numbers in [lo, hi]; an empty cell takes `default` (NaN if None and allowed)."""
    if col not in frame.columns:
        return np.full(len(frame), np.nan if default is None else default)
    text = frame[col]
    values = pd.to_numeric(text.where(text != "", None), errors="coerce").to_numpy(dtype=float, copy=True)
    for row in np.flatnonzero(np.isnan(values) & (text != "").to_numpy()):
        raise InputError(f"{path}: line {_line(row)}: field {col!r}: expected a number, got {text.iloc[row]!r}")
    empty = (text == "").to_numpy()
    if default is not None:
        values[empty] = default
    bad = ~empty & ~((values >= lo) & (values <= hi))
    for row in np.flatnonzero(bad):
        raise InputError(
            f"{path}: line {_line(row)}: field {col!r}: "
            f"expected a finite value in [{lo:g}, {hi:g}], got {text.iloc[row]!r}"
        )
    return values


def parse_time_column(path: Path, frame: pd.DataFrame, col: str) -> NDArray[np.datetime64]:
    """ISO-8601 times as UTC datetime64[ns]; empty cells are NaT; naive times are UTC."""
    if col not in frame.columns:
        return np.full(len(frame), NaT)
    out = np.full(len(frame), NaT)
    text = frame[col]
    present = (text != "").to_numpy()
    if present.any():
        try:
            parsed = pd.to_datetime(text[present], utc=True, format="ISO8601")
        except (ValueError, TypeError, OverflowError):
            for row in np.flatnonzero(present):
                try:
                    pd.to_datetime(text.iloc[row], utc=True, format="ISO8601")
                except (ValueError, TypeError, OverflowError):
                    raise InputError(
                        f"{path}: line {_line(row)}: field {col!r}: expected an ISO-8601 time "
                        f"(e.g. 2009-01-23T00:00:00Z), got {text.iloc[row]!r}"
                    ) from None
            raise
        out[present] = parsed.dt.tz_convert(None).to_numpy(dtype="datetime64[ns]")
    return out


def _require_present(path: Path, frame: pd.DataFrame, col: str) -> None:
    empty = np.flatnonzero((frame[col] == "").to_numpy())
    if len(empty):
        raise InputError(f"{path}: line {_line(empty[0])}: field {col!r} is empty")


# --------------------------------------------------------------------------------------
# beacons.csv


def read_beacons(path: Path) -> BeaconTable:
    """Read `beacons.csv`: beacon_id, lat, lon [, offset_s, start, end, drift_s_per_day]."""
    path = Path(path)
    frame = read_csv_table(path, ("beacon_id", "lat", "lon"), ("offset_s", "start", "end", "drift_s_per_day"))
    if frame.empty:
        raise InputError(f"{path}: no beacons (header only)")
    for col in ("beacon_id", "lat", "lon"):
        _require_present(path, frame, col)
    dup = frame["beacon_id"].duplicated(keep="first").to_numpy()
    if dup.any():
        row = int(np.flatnonzero(dup)[0])
        raise InputError(f"{path}: line {_line(row)}: duplicate beacon_id {frame['beacon_id'].iloc[row]!r}")
    start = parse_time_column(path, frame, "start")
    end = parse_time_column(path, frame, "end")
    inverted = ~np.isnat(start) & ~np.isnat(end) & (end < start)
    for row in np.flatnonzero(inverted):
        raise InputError(f"{path}: line {_line(row)}: field 'end' is before 'start' (no active period)")
    return BeaconTable(
        beacon_id=frame["beacon_id"].to_numpy(dtype=object),
        lat=parse_float_column(path, frame, "lat", lo=-90, hi=90),
        lon=parse_float_column(path, frame, "lon", lo=-180, hi=360),
        offset_s=parse_float_column(path, frame, "offset_s", default=0.0),
        drift_s_per_day=parse_float_column(path, frame, "drift_s_per_day", default=0.0),
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
)


def read_floats(path: Path, model: ModelConfig) -> dict[str, FloatInfo]:
    """Read `floats.csv`; missing window_s / max_signals take the config's values."""
    path = Path(path)
    frame = read_csv_table(path, FLOAT_REQUIRED, FLOAT_OPTIONAL)
    if frame.empty:
        raise InputError(f"{path}: no floats (header only)")
    for col in FLOAT_REQUIRED:
        _require_present(path, frame, col)
    dup = frame["float_id"].duplicated().to_numpy()
    if dup.any():
        row = int(np.flatnonzero(dup)[0])
        raise InputError(f"{path}: line {_line(row)}: duplicate float_id {frame['float_id'].iloc[row]!r}")
    launch_time = parse_time_column(path, frame, "launch_time")
    end_time = parse_time_column(path, frame, "end_time")
    launch_lat = parse_float_column(path, frame, "launch_lat", lo=-90, hi=90)
    launch_lon = parse_float_column(path, frame, "launch_lon", lo=-180, hi=360)
    end_lat = parse_float_column(path, frame, "end_lat", lo=-90, hi=90)
    end_lon = parse_float_column(path, frame, "end_lon", lo=-180, hi=360)
    clock0 = parse_float_column(path, frame, "clock_offset_start_s", default=0.0)
    clock1 = parse_float_column(path, frame, "clock_offset_end_s", default=np.nan)
    window = parse_float_column(path, frame, "window_s", default=model.window_s, lo=1e-9)
    max_sig = parse_float_column(path, frame, "max_signals", default=model.max_signals, lo=1)
    for row in np.flatnonzero(max_sig != np.round(max_sig)):
        raise InputError(f"{path}: line {_line(row)}: field 'max_signals': expected a whole number")
    for row in np.flatnonzero(~np.isnat(end_time) & (end_time <= launch_time)):
        raise InputError(f"{path}: line {_line(row)}: field 'end_time' is not after 'launch_time'")
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
        )
    return floats


# --------------------------------------------------------------------------------------
# <float_id>.csv


def read_arrivals(path: Path, info: FloatInfo, beacons: BeaconTable, warnings: Warnings) -> ArrivalRecord:
    """Read one float's arrival file into windows of ascending TOAs.

    Rows may come in any order. An empty `toa_s` marks a window in which nothing was
    stored. Exact duplicate rows are dropped, TOAs outside [0, window_s] are dropped, and a
    window holding more than `max_signals` TOAs keeps the earliest: each with a warning.
    """
    path = Path(path)
    frame = read_csv_table(path, ("time", "toa_s"), ("quality", "beacon_id"))
    if frame.empty:
        raise InputError(f"{path}: no arrival times (header only)")
    _require_present(path, frame, "time")
    times = parse_time_column(path, frame, "time")
    toa = parse_float_column(path, frame, "toa_s")
    labelled = "beacon_id" in frame.columns
    labels = frame["beacon_id"].to_numpy(dtype=object) if labelled else None
    if labelled:
        known = set(beacons.beacon_id)
        for row, lab in enumerate(labels):
            if lab and lab not in known:
                raise InputError(
                    f"{path}: line {_line(row)}: field 'beacon_id': unknown beacon {lab!r}{nearest(lab, known)}"
                )

    key = pd.DataFrame({"t": times, "toa": toa})
    dup = key.duplicated().to_numpy()
    if dup.any():
        warnings.add(
            f"{path}: {int(dup.sum())} duplicate row(s) dropped (first at line {_line(int(np.flatnonzero(dup)[0]))})"
        )
    outside = ~np.isnan(toa) & ((toa < 0) | (toa > info.window_s))
    if outside.any():
        row = int(np.flatnonzero(outside)[0])
        warnings.add(
            f"{path}: {int(outside.sum())} TOA(s) outside the window [0, {info.window_s:g}] s dropped "
            f"(first at line {_line(row)}: {toa[row]:g})"
        )
    first = times.min()
    if first < info.launch_time:
        row = int(np.argmin(times))
        raise InputError(
            f"{path}: line {_line(row)}: window at {np.datetime_as_string(first, 's')}Z is before the "
            f"float's launch_time {np.datetime_as_string(info.launch_time, 's')}Z"
        )

    # Sort by window, then TOA (empty TOAs last); split into windows at each new time.
    order = np.lexsort((np.nan_to_num(toa, nan=np.inf), times))
    order = order[~dup[order]]
    starts = np.flatnonzero(np.diff(times[order].astype("int64"))) + 1
    windows: list[Window] = []
    truncated = 0
    for group in np.split(order, starts):
        window_time = times[group[0]]
        # A window whose TOAs were all dropped still says "listened, stored nothing".
        rows = group[~np.isnan(toa[group]) & ~outside[group]]
        if len(rows) > info.max_signals:
            truncated += 1
            rows = rows[: info.max_signals]
        win_labels = tuple(lab if lab else None for lab in labels[rows]) if labelled else None
        windows.append(Window(time=window_time, toa_s=toa[rows], beacon_id=win_labels))
    if truncated:
        warnings.add(
            f"{path}: {truncated} window(s) held more than max_signals={info.max_signals} TOAs; kept the earliest"
        )
    return ArrivalRecord(float_id=info.float_id, path=path, windows=tuple(windows))
