"""ARTOA sound-source files (`soso.dat`, `*.soso`): the beacon table.

Only what is publicly documented is accepted: per source its name, position, emission
begin and end, offset and drift. The reader is strict about the layout, since no fuller
specification is public: one source per line, whitespace-separated,

    NAME  LAT  LON  BEGIN  END  OFFSET_S  DRIFT_S_PER_DAY

with LAT/LON in decimal degrees, BEGIN/END ISO-8601 dates or times (UTC; `-` = open), the
offset in seconds after the float's listening window opens (as `beacons.csv`'s `offset_s`)
and the drift in s/day. Lines starting with `%` or `#` and blank lines are comments. Any
other line (another field count, a RAFOS day number for a date, degrees and minutes) is an
error naming the line and saying what is expected.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ..domain import BeaconTable, NaT
from ..errors import InputError
from .csv_table import require_file

_ISO = re.compile(r"^\d{4}-\d{2}-\d{2}([T ]\d{2}:\d{2}(:\d{2}(\.\d+)?)?Z?)?$")
FIELDS = ("name", "lat", "lon", "begin", "end", "offset_s", "drift_s_per_day")


def matches(path: Path) -> bool:
    path = Path(path)
    return path.name.lower() == "soso.dat" or path.suffix.lower() == ".soso"


def _number(path: Path, line: int, field: str, text: str, lo: float = -np.inf, hi: float = np.inf) -> float:
    try:
        value = float(text)
    except ValueError:
        raise InputError(f"{path}: line {line}: field {field!r}: expected a number, got {text!r}") from None
    if not (np.isfinite(value) and lo <= value <= hi):
        raise InputError(
            f"{path}: line {line}: field {field!r}: expected a finite number in [{lo:g}, {hi:g}], got {text!r}"
        )
    return value


def _time(path: Path, line: int, field: str, text: str) -> np.datetime64:
    if text == "-":
        return NaT
    try:
        if not _ISO.match(text):
            raise ValueError(text)
        return np.datetime64(text.removesuffix("Z"), "ns")
    except ValueError:
        what = (
            " (a RAFOS day number? its epoch varies between tools: write the date)"
            if text.replace(".", "").isdigit()
            else ""
        )
        raise InputError(
            f"{path}: line {line}: field {field!r}: expected an ISO-8601 date or time or '-', got {text!r}{what}"
        ) from None


def read_beacons(path: Path) -> BeaconTable:
    """The sources of an ARTOA sound-source file (module docstring)."""
    path = Path(path)
    require_file(path, "expected an ARTOA sound-source file")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise InputError(f"{path}: not UTF-8 text; expected an ARTOA sound-source text file") from None
    rows: list[tuple] = []
    seen: dict[str, int] = {}
    for line_no, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if not stripped or stripped[0] in "%#":
            continue
        fields = stripped.split()
        if len(fields) != len(FIELDS):
            raise InputError(
                f"{path}: line {line_no}: {len(fields)} fields; expected {len(FIELDS)}: {' '.join(FIELDS)} "
                "(the documented fields of an ARTOA sound-source file; no other layout is publicly specified)"
            )
        name = fields[0]
        if name in seen:
            raise InputError(f"{path}: line {line_no}: source {name!r} again (first on line {seen[name]})")
        seen[name] = line_no
        begin, end = _time(path, line_no, "begin", fields[3]), _time(path, line_no, "end", fields[4])
        if not np.isnat(begin) and not np.isnat(end) and end < begin:
            raise InputError(f"{path}: line {line_no}: field 'end' is before 'begin'; expected end >= begin")
        rows.append(
            (
                name,
                _number(path, line_no, "lat", fields[1], -90, 90),
                _number(path, line_no, "lon", fields[2], -180, 360),
                begin,
                end,
                _number(path, line_no, "offset_s", fields[5]),
                _number(path, line_no, "drift_s_per_day", fields[6]),
            )
        )
    if not rows:
        raise InputError(f"{path}: no sources; expected lines of {' '.join(FIELDS)}")
    columns = list(zip(*rows, strict=True))
    return BeaconTable(
        beacon_id=np.array(columns[0], dtype=object),
        lat=np.array(columns[1], dtype=float),
        lon=np.array(columns[2], dtype=float),
        offset_s=np.array(columns[5], dtype=float),
        drift_s_per_day=np.array(columns[6], dtype=float),
        start=np.array(columns[3], dtype="datetime64[ns]"),
        end=np.array(columns[4], dtype="datetime64[ns]"),
    )
