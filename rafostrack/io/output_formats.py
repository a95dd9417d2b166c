"""The result tables in the formats users take elsewhere: Parquet, CSV, CF NetCDF, ARTOA `.rfc`.

`write_estimate(out_dir, estimate, info, formats, metadata, suffix)` writes one estimate's
tables in every format asked for (`OUTPUT_FORMATS`), each file atomically:

- `parquet`: track, labels and modes, with run metadata in the schema and units per field.
- `csv`: the same three tables as CSV (times ISO-8601 with Z, empty = missing).
- `netcdf`: `track.nc`, a CF-1.8 `featureType = trajectory` file (one trajectory: the float)
  with units, long and standard names, readable by xarray, and `labels.nc`, the labels
  table, each TOA linked to its window of `track.nc` by a CF indexed ragged array
  (`io.netcdf`: the layout and why it is a second file, not a group).
- `rfc`: `<float_id>.rfc`, the ARTOA track text: `**` header lines, then one line per window
  of 10 right-aligned 12-character columns InterpFlag LineNum RafosDay Temp Pres Lat Lon U V
  W (units # # # degC dbar deg deg cm/s cm/s mm/s). InterpFlag 0 where arrival times
  support the position (status ok or ambiguous), 1 where the drift model carries it; RafosDay
  = Julian day - 2440000 (`RAFOS_DAY_EPOCH`); U, V from the track by centred differences;
  Temp, Pres and W are not measured here and hold the dummies -9.99, -999 and 999.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..domain import FloatInfo
from ..errors import InputError, nearest
from ..model.geodesy import local_offsets_km
from .atomic import write_text_atomic
from .netcdf import write_labels_netcdf, write_netcdf
from .writers import write_parquet

OUTPUT_FORMATS = ("parquet", "csv", "netcdf", "rfc")
# RAFOS day 0: Julian day 2440000.0 (RafosDay = JD - 2440000), as ARTOA counts days.
RAFOS_DAY_EPOCH = np.datetime64("1968-05-23T12:00:00", "ns")
RFC_COLUMNS = ("InterpFlag", "LineNum", "RafosDay", "Temp", "Pres", "Lat", "Lon", "U", "V", "W")
RFC_UNITS = ("#", "#", "#", "degC", "dbar", "deg", "deg", "cm/s", "cm/s", "mm/s")
RFC_DUMMY = {"Temp": -9.99, "Pres": -999.0, "W": 999.0}
RFC_WIDTH = 12


def parse_formats(text: str | Sequence[str]) -> tuple[str, ...]:
    """`"parquet,csv"` (or a sequence) as checked format names, in the order given."""
    names = [n.strip().lower() for n in (text.split(",") if isinstance(text, str) else text) if n.strip()]
    for name in names:
        if name not in OUTPUT_FORMATS:
            raise InputError(
                f"--format: unknown output format {name!r}{nearest(name, OUTPUT_FORMATS)}; "
                f"expected a comma-separated list of {', '.join(OUTPUT_FORMATS)}"
            )
    if not names:
        raise InputError(f"--format: no output format given; expected some of {', '.join(OUTPUT_FORMATS)}")
    return tuple(dict.fromkeys(names))


def rafos_day(times: np.ndarray) -> np.ndarray:
    """Days (fractional) since `RAFOS_DAY_EPOCH`."""
    return (np.asarray(times, dtype="datetime64[ns]") - RAFOS_DAY_EPOCH) / np.timedelta64(1, "D")


def write_estimate(
    out_dir: Path,
    tables: dict[str, pd.DataFrame],
    info: FloatInfo,
    formats: Sequence[str],
    metadata: dict[str, Any],
    suffix: str = "",
) -> list[Path]:
    """Write `tables` ("track", "labels", "modes") in every format of `formats` into `out_dir`."""
    out_dir = Path(out_dir)
    written: list[Path] = []
    for fmt in formats:
        if fmt == "parquet":
            for name, frame in tables.items():
                path = out_dir / f"{name}{suffix}.parquet"
                write_parquet(frame, path, metadata, table_name=name)
                written.append(path)
        elif fmt == "csv":
            for name, frame in tables.items():
                path = out_dir / f"{name}{suffix}.csv"
                write_csv(frame, path)
                written.append(path)
        elif fmt == "netcdf":
            track_path, labels_path = out_dir / f"track{suffix}.nc", out_dir / f"labels{suffix}.nc"
            write_netcdf(tables["track"], info, track_path, metadata)
            write_labels_netcdf(tables["labels"], tables["track"], info, labels_path, metadata, track_path.name)
            written += [track_path, labels_path]
        elif fmt == "rfc":
            path = out_dir / f"{info.float_id}{suffix}.rfc"
            write_rfc(tables["track"], info, path, metadata)
            written.append(path)
        else:
            raise ValueError(f"unknown output format {fmt!r}")
    return written


def write_csv(frame: pd.DataFrame, path: Path) -> None:
    """`frame` as CSV: times ISO-8601 UTC with a Z, floats at full precision, missing empty."""
    frame = frame.copy()
    if "time" in frame:
        frame["time"] = pd.to_datetime(frame["time"]).dt.strftime("%Y-%m-%dT%H:%M:%SZ")
    write_text_atomic(path, frame.to_csv(index=False, lineterminator="\n"))


def _velocity_cm_s(track: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
    """East and north velocity (cm/s) by centred differences (one-sided at the ends)."""
    n = len(track)
    if n < 2:
        return np.full(n, np.nan), np.full(n, np.nan)
    t = pd.to_datetime(track["time"]).to_numpy(dtype="datetime64[ns]").astype(np.int64) / 1e9
    lat, lon = track["lat"].to_numpy(dtype=float), track["lon"].to_numpy(dtype=float)
    i0 = np.clip(np.arange(n) - 1, 0, n - 1)
    i1 = np.clip(np.arange(n) + 1, 0, n - 1)
    east, north = local_offsets_km(lat[i1], lon[i1], lat[i0], lon[i0])
    dt = t[i1] - t[i0]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.asarray(east) * 1e5 / dt, np.asarray(north) * 1e5 / dt


def rfc_text(track: pd.DataFrame, info: FloatInfo, metadata: dict[str, Any]) -> str:
    """The ARTOA `.rfc` track text (module docstring)."""
    u, v = _velocity_cm_s(track)
    status = track["status"].astype(str).to_numpy() if "status" in track else np.full(len(track), "ok")
    interp = np.where(np.isin(status, ("ok", "ambiguous")), 0, 1)
    times = pd.to_datetime(track["time"]).dt.tz_localize(None).to_numpy(dtype="datetime64[ns]")
    rows = {
        "InterpFlag": interp,
        "LineNum": np.arange(1, len(track) + 1),
        "RafosDay": rafos_day(times),
        "Temp": np.full(len(track), RFC_DUMMY["Temp"]),
        "Pres": np.full(len(track), RFC_DUMMY["Pres"]),
        "Lat": track["lat"].to_numpy(dtype=float),
        "Lon": track["lon"].to_numpy(dtype=float),
        "U": np.nan_to_num(u, nan=RFC_DUMMY["W"]),
        "V": np.nan_to_num(v, nan=RFC_DUMMY["W"]),
        "W": np.full(len(track), RFC_DUMMY["W"]),
    }
    formats = {"InterpFlag": "{:12d}", "LineNum": "{:12d}", "RafosDay": "{:12.4f}", "Lat": "{:12.5f}",
               "Lon": "{:12.5f}"}  # fmt: skip
    lines = [
        f"** RAFOS float {info.float_id}: track estimated by rafostrack {metadata.get('version', '')} "
        f"({metadata.get('estimate', '')})",
        "** " + "".join(f"{c:>{RFC_WIDTH}}" for c in RFC_COLUMNS),
        "** " + "".join(f"{c:>{RFC_WIDTH}}" for c in RFC_UNITS),
        "** RafosDay = Julian day - 2440000 (day 0 = 1968-05-23T12:00Z); InterpFlag 0 = from arrival times, "
        "1 = drift model only",
        "** dummies: " + ", ".join(f"{k} {v:g}" for k, v in RFC_DUMMY.items()) + " (not measured)",
    ]
    for k in range(len(track)):
        lines.append("".join(formats.get(c, "{:12.2f}").format(rows[c][k]) for c in RFC_COLUMNS))
    return "\n".join(lines) + "\n"


def write_rfc(track: pd.DataFrame, info: FloatInfo, path: Path, metadata: dict[str, Any]) -> None:
    write_text_atomic(path, rfc_text(track, info, metadata))


def read_rfc(path: Path) -> pd.DataFrame:
    """An `.rfc` file's rows as a frame with the columns `RFC_COLUMNS` (dummies kept)."""
    rows = []
    for line in Path(path).read_text(encoding="utf-8").splitlines():
        if line.startswith("**") or not line.strip():
            continue
        fields = [line[i : i + RFC_WIDTH] for i in range(0, RFC_WIDTH * len(RFC_COLUMNS), RFC_WIDTH)]
        rows.append([float(f) for f in fields])
    return pd.DataFrame(rows, columns=list(RFC_COLUMNS))
