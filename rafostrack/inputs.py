"""Read and validate a mission: `beacons.csv`, `floats.csv` and one arrival file per float.

Every problem a user can fix raises `InputError` with the file, the line (as a text editor
counts them, header = line 1) and the field; recoverable oddities are recorded in a
`Warnings` list. Times are ISO-8601; a time without a zone is taken as UTC. All times are
held as UTC `numpy.datetime64[ns]`.
"""

from __future__ import annotations

import codecs
import csv
import os
import warnings as pywarnings
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

_EXTRA = "\x00extra"  # sentinel column: a row with more fields than the header fills it
_CHUNK = 1 << 20  # bytes per chunk when checking the encoding
_ROWS_PER_CHUNK = 100_000  # rows per chunk when parsing
# Times must fit numpy's datetime64[ns]: years 1678-2261.
_TIME_MIN = pd.Timestamp("1678-01-01", tz="UTC")
_TIME_MAX = pd.Timestamp("2261-12-31", tz="UTC")
# A stretch longer than this with no window that has an active beacon and a stored TOA is
# warned about (the track there follows the drift model only).
USABLE_GAP_DAYS = 10.0
_LIST_MAX = 5  # how many windows / stretches a warning lists before "and N more"


def _time_text(t: np.datetime64) -> str:
    return f"{np.datetime_as_string(t, 's')}Z"


def _line_breaks(data: bytes) -> int:
    return data.count(b"\n") + data.count(b"\r") - data.count(b"\r\n")


def _check_utf8(path: Path) -> bool:
    """Decode the file in chunks (bounded memory); a bad byte is an error naming its line.
    Returns whether the file holds a quote character (only then can a field hold a line break)."""
    decoder = codecs.getincrementaldecoder("utf-8-sig")(errors="strict")
    lines_before = 0
    quoted = False
    with open(path, "rb") as fh:
        while True:
            chunk = fh.read(_CHUNK)
            pending = len(decoder.getstate()[0])
            try:
                decoder.decode(chunk, final=not chunk)
            except UnicodeDecodeError as exc:
                line = lines_before + _line_breaks(chunk[: max(exc.start - pending, 0)]) + 1
                bad = exc.object[exc.start : exc.start + 1]
                raise InputError(
                    f"{path}: line {line}: not UTF-8 text (byte 0x{bad.hex() or '??'}); "
                    "expected a UTF-8 (or ASCII) CSV file"
                ) from None
            if not chunk:
                return quoted
            lines_before += _line_breaks(chunk)
            quoted = quoted or b'"' in chunk


def _read_header(path: Path, required: tuple[str, ...]) -> tuple[list[str], int]:
    """The header's column names and the number of lines it (and blank lines before it) took."""
    try:
        with open(path, encoding="utf-8-sig", newline="") as fh:
            reader = csv.reader(fh, skipinitialspace=True)
            for fields in reader:
                if any(f.strip() for f in fields):
                    return [f.strip() for f in fields], reader.line_num
    except csv.Error as exc:
        raise InputError(f"{path}: line 1: cannot parse the header as CSV ({exc})") from None
    raise InputError(f"{path}: file is empty (expected a header line: {', '.join(required)})")


def _check_header(path: Path, header: list[str], line: int, required: tuple[str, ...], optional: tuple[str, ...]):
    known = (*required, *optional)
    where = f"{path}: line {line}"
    if len(header) == 1:
        for sep, name in ((";", "';'"), ("\t", "tabs"), ("|", "'|'")):
            if sep in header[0]:
                raise InputError(
                    f"{where}: columns are separated by {name}; expected ',' (comma-separated CSV with columns "
                    f"{', '.join(required)})"
                )
    for i, col in enumerate(header):
        if "\n" in col or "\r" in col:
            raise InputError(f"{where}: column {i + 1} name contains a line break (an unclosed quote?)")
        if not col:
            raise InputError(
                f"{where}: column {i + 1} has no name (a trailing comma?); expected only the columns {', '.join(known)}"
            )
    for col in required:
        if col not in header:
            raise InputError(f"{where}: missing required column {col!r}{nearest(col, header)}")
    for col in header:
        if col not in known:
            hint = nearest(col, known) or f" (expected only {', '.join(known)})"
            raise InputError(f"{where}: unknown column {col!r}{hint}")
    seen: set[str] = set()
    for col in header:
        if col in seen:
            raise InputError(f"{where}: column {col!r} appears twice; expected each column once")
        seen.add(col)


def _raise_long_row(path: Path, header: list[str], header_lines: int) -> None:
    """Raise for the first row with more (non-empty) fields than the header; a slow pass,
    only taken when pandas has met such a row. Returns if every extra field is empty."""
    n = len(header)
    with open(path, encoding="utf-8-sig", newline="") as fh:
        reader = csv.reader(fh, skipinitialspace=True)
        start = 1
        try:
            for fields in reader:
                if reader.line_num > header_lines and len(fields) > n and any(f.strip() for f in fields[n:]):
                    raise InputError(
                        f"{path}: line {start}: {len(fields)} fields; expected {n} "
                        f"(as many as the header: {', '.join(header)})"
                    )
                start = reader.line_num + 1
        except csv.Error as exc:
            raise InputError(f"{path}: line {start}: cannot parse as CSV ({exc})") from None


def read_csv_table(path: Path, required: tuple[str, ...], optional: tuple[str, ...]) -> pd.DataFrame:
    """Read a CSV as stripped text columns after checking its header.

    The frame's index holds each row's line number in the file (as a text editor counts
    them, header = line 1); blank lines are skipped. Fewer fields than the header means
    the missing trailing fields are empty; more fields is an error.
    """
    path = Path(path)
    expected = f"expected a CSV file with columns {', '.join(required)}"
    if not path.exists():
        raise InputError(f"{path}: file not found ({expected})")
    if not path.is_file():
        raise InputError(f"{path}: not a regular file ({expected})")
    try:
        quoted = _check_utf8(path)
        header, header_lines = _read_header(path, required)
    except OSError as exc:
        raise InputError(f"{path}: cannot read: {exc.strerror or exc}") from None
    _check_header(path, header, header_lines, required, optional)
    try:
        with pywarnings.catch_warnings(record=True) as caught:
            # pandas only warns (and drops the extra fields) when a row has more fields than
            # the names given; make that an error below.
            pywarnings.simplefilter("always", pd.errors.ParserWarning)
            # In chunks: the parser's temporary Python strings then stay bounded.
            with pd.read_csv(
                path,
                header=None,
                names=[*header, _EXTRA],
                skiprows=header_lines,
                dtype=str,
                keep_default_na=False,
                na_filter=False,
                encoding="utf-8-sig",
                skipinitialspace=True,
                index_col=False,
                skip_blank_lines=False,
                engine="c",
                chunksize=_ROWS_PER_CHUNK,
            ) as chunks:
                parts = list(chunks)
        frame = pd.concat(parts, ignore_index=True) if parts else None
    except pd.errors.EmptyDataError:
        frame = None
    except pd.errors.ParserError as exc:
        text = str(exc).strip()
        if "Expected" in text and "fields" in text:
            _raise_long_row(path, header, header_lines)
            raise InputError(f"{path}: a row has more fields than the header; expected {len(header)}") from None
        reason = text.splitlines()[0] if text else type(exc).__name__
        if "EOF inside string" in reason:
            reason = 'a quote (") is never closed'
        raise InputError(f"{path}: cannot parse as CSV: {reason}") from None
    except (ValueError, UnicodeError, OSError, OverflowError) as exc:
        reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise InputError(f"{path}: cannot parse as CSV: {reason}") from None
    if any(issubclass(w.category, pd.errors.ParserWarning) for w in caught):
        _raise_long_row(path, header, header_lines)
    if frame is None:
        frame = pd.DataFrame({c: pd.Series([], dtype=str) for c in [*header, _EXTRA]})
    frame.index = pd.RangeIndex(header_lines + 1, header_lines + 1 + len(frame))
    broken = np.zeros(len(frame), dtype=bool)
    for col in frame.columns if quoted else ():
        broken |= (
            frame[col].str.contains("\n", regex=False).to_numpy()
            | frame[col].str.contains("\r", regex=False).to_numpy()
        )
    if broken.any():
        line = int(frame.index[np.argmax(broken)])
        raise InputError(f"{path}: line {line}: a field contains a line break (an unclosed quote?)")
    frame = frame.apply(lambda c: c.str.strip())
    extra = (frame[_EXTRA] != "").to_numpy()
    if extra.any():
        line = int(frame.index[np.argmax(extra)])
        raise InputError(
            f"{path}: line {line}: more fields than the header; expected {len(header)} ({', '.join(header)})"
        )
    frame = frame.drop(columns=_EXTRA)
    blank = np.ones(len(frame), dtype=bool)
    for col in frame.columns:
        blank &= (frame[col] == "").to_numpy()
    if blank.any():
        frame = frame[~blank]
    frame.attrs["first_data_line"] = header_lines + 1
    return frame


def _line(frame: pd.DataFrame, row: int) -> int:
    """The file line of positional row `row` (see `read_csv_table`)."""
    return int(frame.index[row])


def _looks_numeric(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def parse_float_column(
    path: Path,
    frame: pd.DataFrame,
    col: str,
    *,
    default: float | None = None,
    lo: float = -np.inf,
    hi: float = np.inf,
    expect: str | None = None,
) -> NDArray[np.float64]:
    """Finite numbers in [lo, hi] (`expect` describes the range in messages); an empty cell
    takes `default` (NaN if None)."""
    if col not in frame.columns:
        return np.full(len(frame), np.nan if default is None else default)
    text = frame[col]
    empty = (text == "").to_numpy()
    values = pd.to_numeric(text.where(~empty, None), errors="coerce")
    values = np.asarray(values, dtype=float).copy()
    if expect is None:
        expect = f"in [{lo:g}, {hi:g}]" if np.isfinite(lo) and np.isfinite(hi) else ""
        expect = expect or (f">= {lo:g}" if np.isfinite(lo) else f"<= {hi:g}" if np.isfinite(hi) else "")
    bad = ~empty & ~np.isfinite(values)
    if bad.any():
        row = int(np.argmax(bad))
        got = text.iloc[row]
        where = f"{path}: line {_line(frame, row)}: field {col!r}"
        if _looks_numeric(got):
            raise InputError(f"{where}: expected a finite number{' ' + expect if expect else ''}, got {got!r}")
        raise InputError(f"{where}: expected a number, got {got!r}{' (a value ' + expect + ')' if expect else ''}")
    if default is not None:
        values[empty] = default
    out = ~empty & ~((values >= lo) & (values <= hi))
    if out.any():
        row = int(np.argmax(out))
        raise InputError(
            f"{path}: line {_line(frame, row)}: field {col!r}: expected a finite value {expect}, got {text.iloc[row]!r}"
        )
    return values


def parse_time_column(path: Path, frame: pd.DataFrame, col: str) -> NDArray[np.datetime64]:
    """ISO-8601 times as UTC datetime64[ns]; empty cells are NaT; times without a zone are UTC."""
    out = np.full(len(frame), NaT)
    if col not in frame.columns:
        return out
    text = frame[col]
    present = (text != "").to_numpy()
    if present.any():
        # Arrival files repeat each window's time for every TOA: parse each distinct text once.
        codes, uniques = pd.factorize(text[present])
        parsed = pd.to_datetime(pd.Series(uniques, dtype=str), utc=True, format="ISO8601", errors="coerce")
        ok = (parsed.notna() & (parsed >= _TIME_MIN) & (parsed <= _TIME_MAX)).to_numpy()
        if not ok.all():
            row = int(np.flatnonzero(present)[np.argmax(~ok[codes])])
            raise InputError(
                f"{path}: line {_line(frame, row)}: field {col!r}: expected an ISO-8601 time "
                f"(e.g. 2009-01-23T00:00:00Z, years 1678-2261), got {text.iloc[row]!r}"
            )
        out[present] = parsed.dt.tz_convert(None).dt.as_unit("ns").to_numpy(dtype="datetime64[ns]")[codes]
    return out


def _require_present(path: Path, frame: pd.DataFrame, col: str, expect: str = "a value") -> None:
    empty = (frame[col] == "").to_numpy()
    if empty.any():
        line = _line(frame, int(np.argmax(empty)))
        raise InputError(f"{path}: line {line}: field {col!r} is empty; expected {expect}")


def _first_duplicate(path: Path, frame: pd.DataFrame, col: str) -> None:
    dup = frame[col].duplicated(keep="first").to_numpy()
    if dup.any():
        row = int(np.argmax(dup))
        value = frame[col].iloc[row]
        first = int(np.argmax((frame[col] == value).to_numpy()))
        raise InputError(
            f"{path}: line {_line(frame, row)}: duplicate {col} {value!r} (first on line {_line(frame, first)}); "
            f"field {col!r}: expected each id once"
        )


def _header_only(path: Path, frame: pd.DataFrame, what: str) -> InputError:
    line = frame.attrs.get("first_data_line", 2)
    return InputError(f"{path}: line {line}: no rows after the header (header only); expected at least one {what}")


# --------------------------------------------------------------------------------------
# beacons.csv


def read_beacons(path: Path) -> BeaconTable:
    """Read `beacons.csv`: beacon_id, lat, lon [, offset_s, start, end, drift_s_per_day]."""
    path = Path(path)
    frame = read_csv_table(path, ("beacon_id", "lat", "lon"), ("offset_s", "start", "end", "drift_s_per_day"))
    if frame.empty:
        raise _header_only(path, frame, "beacon")
    _require_present(path, frame, "beacon_id", "a text id")
    _first_duplicate(path, frame, "beacon_id")
    lat = parse_float_column(path, frame, "lat", lo=-90, hi=90)
    lon = parse_float_column(path, frame, "lon", lo=-180, hi=360)
    for col in ("lat", "lon"):
        _require_present(path, frame, col, "a position in degrees")
    offset = parse_float_column(path, frame, "offset_s", default=0.0)
    drift = parse_float_column(path, frame, "drift_s_per_day", default=0.0)
    start = parse_time_column(path, frame, "start")
    end = parse_time_column(path, frame, "end")
    inverted = ~np.isnat(start) & ~np.isnat(end) & (end < start)
    if inverted.any():
        row = int(np.argmax(inverted))
        raise InputError(
            f"{path}: line {_line(frame, row)}: field 'end': {_time_text(end[row])} is before 'start' "
            f"{_time_text(start[row])}; expected end >= start (or empty)"
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
)


def read_floats(path: Path, model: ModelConfig) -> dict[str, FloatInfo]:
    """Read `floats.csv`; missing window_s / max_signals take the config's values."""
    path = Path(path)
    frame = read_csv_table(path, FLOAT_REQUIRED, FLOAT_OPTIONAL)
    if frame.empty:
        raise _header_only(path, frame, "float")
    _require_present(path, frame, "float_id", "the arrival file's name, e.g. float767")
    _first_duplicate(path, frame, "float_id")
    _require_present(path, frame, "launch_time", "an ISO-8601 time")
    launch_time = parse_time_column(path, frame, "launch_time")
    end_time = parse_time_column(path, frame, "end_time")
    launch_lat = parse_float_column(path, frame, "launch_lat", lo=-90, hi=90)
    launch_lon = parse_float_column(path, frame, "launch_lon", lo=-180, hi=360)
    for col in ("launch_lat", "launch_lon"):
        _require_present(path, frame, col, "a position in degrees")
    end_lat = parse_float_column(path, frame, "end_lat", lo=-90, hi=90)
    end_lon = parse_float_column(path, frame, "end_lon", lo=-180, hi=360)
    clock0 = parse_float_column(path, frame, "clock_offset_start_s", default=0.0)
    clock1 = parse_float_column(path, frame, "clock_offset_end_s")
    window = parse_float_column(path, frame, "window_s", default=model.window_s, lo=1e-9, expect="> 0")
    max_sig = parse_float_column(path, frame, "max_signals", default=model.max_signals, lo=1, hi=1e6)
    for row in np.flatnonzero(max_sig != np.round(max_sig))[:1]:
        raise InputError(
            f"{path}: line {_line(frame, row)}: field 'max_signals': expected a whole number >= 1, "
            f"got {frame['max_signals'].iloc[row]!r}"
        )
    for row in np.flatnonzero(np.isnan(end_lat) != np.isnan(end_lon))[:1]:
        col = "end_lon" if np.isnan(end_lon[row]) else "end_lat"
        raise InputError(
            f"{path}: line {_line(frame, row)}: field {col!r} is empty; expected both end_lat and end_lon, or neither"
        )
    for row in np.flatnonzero(~np.isnan(end_lat) & np.isnat(end_time))[:1]:
        raise InputError(
            f"{path}: line {_line(frame, row)}: field 'end_time' is empty; expected the time of the end fix "
            "given by end_lat, end_lon"
        )
    for row in np.flatnonzero(~np.isnat(end_time) & (end_time <= launch_time))[:1]:
        raise InputError(
            f"{path}: line {_line(frame, row)}: field 'end_time': {_time_text(end_time[row])} is not after "
            f"launch_time {_time_text(launch_time[row])}; expected a later time (or empty)"
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
        )
    return floats


# --------------------------------------------------------------------------------------
# <float_id>.csv


def _list_runs(times: NDArray[np.datetime64], flagged: NDArray[np.bool_]) -> str:
    """Consecutive flagged windows as 'T' or 'T1 to T2 (n windows)', the first few of them."""
    idx = np.flatnonzero(flagged)
    runs = np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1)
    parts = [
        _time_text(times[r[0]])
        if len(r) == 1
        else f"{_time_text(times[r[0]])} to {_time_text(times[r[-1]])} ({len(r)} windows)"
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
        raise _header_only(path, frame, "row (time, toa_s)")
    _require_present(path, frame, "time", "the window's opening time (ISO-8601)")
    times = parse_time_column(path, frame, "time")
    toa = parse_float_column(path, frame, "toa_s")
    lines = frame.index.to_numpy()
    labelled = "beacon_id" in frame.columns
    labels = frame["beacon_id"].to_numpy(dtype=object) if labelled else None
    if labelled:
        known = [str(b) for b in beacons.beacon_id]
        unknown = ((frame["beacon_id"] != "") & ~frame["beacon_id"].isin(known)).to_numpy()
        if unknown.any():
            row = int(np.argmax(unknown))
            lab = labels[row]
            hint = nearest(lab, known) or " (expected a beacon_id of the beacons table or empty for clutter)"
            raise InputError(f"{path}: line {lines[row]}: field 'beacon_id': unknown beacon {lab!r}{hint}")
    first = int(np.argmin(times))
    if times[first] < info.launch_time:
        raise InputError(
            f"{path}: line {lines[first]}: window at {_time_text(times[first])} is before the float's "
            f"launch_time {_time_text(info.launch_time)}; field 'time': expected windows at or after the launch "
            "(check launch_time in floats.csv)"
        )

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
            f"kept the earliest (first: window {_time_text(t_sorted[r])}, line {lines[order[r]]} left out)"
        )
    mixed = (n_empty_rows > 0) & (n_toa_rows > 0)
    if mixed.any():
        w = int(np.argmax(mixed))
        warnings.add(
            f"{path}: {int(mixed.sum())} window(s) have both an empty toa_s row and TOAs; the empty row was "
            f"ignored (first: window {_time_text(win_times[w])})"
        )
    close = np.flatnonzero(np.diff(win_times) / np.timedelta64(1, "s") < info.window_s)
    if len(close):
        w = int(close[0]) + 1
        warnings.add(
            f"{path}: {len(close)} window(s) open less than window_s={info.window_s:g} s after the previous one "
            f"(first: window {_time_text(win_times[w])}, line {lines[order[bounds[w]]]}); expected one "
            "opening time per window, shared by all its TOAs"
        )

    n_stored = np.bincount(win_of_row[stored], minlength=n_win)
    _warn_beaconless(path, info, beacons, win_times, n_stored, warnings)

    toa_stored = toa[order][stored]
    splits = np.cumsum(n_stored)[:-1]
    toa_groups = np.split(toa_stored, splits)
    if labelled:
        lab_groups = np.split(labels[order][stored], splits)
        label_tuples = [tuple(lab if lab else None for lab in g) for g in lab_groups]
    else:
        label_tuples = [None] * n_win
    windows = tuple(
        Window(time=t, toa_s=g, beacon_id=lab) for t, g, lab in zip(win_times, toa_groups, label_tuples, strict=True)
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
            f"{_time_text(anchors[i])} to {_time_text(anchors[i + 1])} ({gap_days[i]:.1f} days)"
            for i in long[:_LIST_MAX]
        ]
        more = f"; and {len(long) - _LIST_MAX} more" if len(long) > _LIST_MAX else ""
        warnings.add(
            f"{path}: no usable beacon (no window with an active beacon and a stored TOA) for more than "
            f"{USABLE_GAP_DAYS:g} days: {'; '.join(parts)}{more}; the track there follows the drift model only"
        )


# --------------------------------------------------------------------------------------
# Output directory


def check_output_dir(path: Path) -> None:
    """Fail before any work when `path` cannot be an output directory: it, or the nearest
    ancestor that exists, is not a directory, or that directory is not writable."""
    path = Path(path)
    probe = path
    while not probe.exists() and probe.parent != probe:
        probe = probe.parent
    if probe.exists() and not probe.is_dir():
        what = "is a file" if probe == path else f"cannot be created: {probe} is a file"
        what += ", not a directory"
        raise InputError(f"{path}: output directory {what}; expected --out to name a writable directory")
    if probe.is_dir() and not os.access(probe, os.W_OK | os.X_OK):
        raise InputError(
            f"{path}: output directory is not writable ({probe} denies write access); "
            "expected --out to name a writable directory"
        )
