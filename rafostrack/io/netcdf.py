"""CF NetCDF outputs: the track (`track.nc`) and every TOA's label (`labels.nc`), with h5netcdf.

`track.nc` is a CF-1.8 discrete sampling geometry, `featureType = trajectory`: one
trajectory (the float: scalar `trajectory`, `cf_role = trajectory_id`), one element per
listening window (dimension `obs`), `time`, `lat`, `lon` its coordinates.

`labels.nc` holds the labels table, one row per stored TOA (dimension `label`): every column
under its own name (`float_id` a scalar, `time` the window's opening, the label's coordinate).
A window's TOAs are a CF indexed ragged array whose instances are the windows of `track.nc`:
`window_index(label)` is the zero-based `obs` row of the TOA's window there, with
`instance_dimension = "obs"`, and `labels.nc` declares the dimension `obs` with the length of
`track.nc`'s (no variable of its own: the windows' variables are `track.nc`'s).

Why a second file, and neither a group of `track.nc` nor more variables in its root group:

- `xarray.open_dataset` reads only the root group (a group needs `group=`), CF before 1.8
  has no groups (1.8 only scopes names with them), and many readers ignore them;
- in `track.nc`'s root, a variable with `instance_dimension` is read by a CF reader as the
  trajectory file's own ragged index (every window a trajectory), and a second dimension
  makes xarray's `to_dataframe()` the product of both;
- `labels.nc` is no discrete sampling geometry (no `featureType`): a TOA has no position of
  its own, and a trajectory's mandatory `lat`, `lon` per element would copy the track onto
  every TOA. Left a plain CF table, `xarray.open_dataset("labels.nc").to_dataframe()` is the
  labels table.

Attributes come from the column descriptions (`io.columns`), as the Parquet writer's field
metadata do: `long_name` the description, `units` and CF `standard_name` where the column
has them (not on `time`, whose units the encoding writes: seconds since 1970-01-01, UTC).
Missing values: floats NaN (`_FillValue = NaN`, xarray's), text `_FillValue = ""` (a
clutter TOA's `beacon_id`: null in Parquet, NaN from xarray); integers and flags are never
missing and carry none. Categorical columns with a fixed set of values are CF flags
(`flag_values`, `flag_meanings`: the track's `ambiguous`, and its `status`, int8, flag value
i meaning `STATUSES[i]`); `beacon_id` stays text, since beacon ids are the user's own strings
and CF allows in a flag meaning only letters, digits and `_-.+@`. Every numeric array is
zlib-compressed (`ZLIB`); the variable-length text is not (HDF5 cannot compress it).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..domain import FloatInfo
from .atomic import atomic_path
from .columns import LABELS, TIME, TRACK, Column

TIME_UNITS = "seconds since 1970-01-01 00:00:00"
# track.nc's `status` as CF flags: flag value i means STATUSES[i] (`summaries.estimates.window_status`)
STATUSES = ("ok", "ambiguous", "unsupported", "recovered")
ZLIB = {"zlib": True, "complevel": 4}  # the encoding of every numeric array (`_compress`)
WINDOW_DIM = "obs"  # track.nc's element dimension: one listening window each
LABEL_DIM = "label"  # labels.nc's: one stored TOA each
TEXT_FILL = ""  # _FillValue of text variables (missing = empty, as in the CSV tables)


def cf_attrs(spec: Column) -> dict[str, Any]:
    """A column's CF attributes: `long_name`, and `units`, `standard_name` where it has them."""
    attrs: dict[str, Any] = {"long_name": spec.description}
    if spec.units:
        attrs["units"] = spec.units
    if spec.standard_name:
        attrs["standard_name"] = spec.standard_name
    return attrs


def utc_naive(times: pd.Series) -> np.ndarray:
    """Times as UTC datetime64[ns] without a zone (a zoned series converted to UTC first)."""
    times = pd.to_datetime(times)
    if times.dt.tz is not None:
        times = times.dt.tz_convert("UTC").dt.tz_localize(None)
    return times.to_numpy(dtype="datetime64[ns]")


def _time_coord(times: np.ndarray, dim: str) -> tuple[str, np.ndarray, dict[str, Any]]:
    """The `time` coordinate along `dim` (its units are the encoding's, `TIME_UNITS`)."""
    return (dim, times, {"standard_name": TIME.standard_name, "long_name": TIME.description, "axis": "T"})


def _global_attrs(info: FloatInfo, metadata: dict[str, Any], what: str) -> dict[str, Any]:
    return {
        "Conventions": "CF-1.8",
        "title": f"RAFOS float {info.float_id}: {what} estimated by rafostrack",
        "source": f"rafostrack {metadata.get('version', '')}: ranked-signal particle filter and smoother",
        "rafostrack_estimate": str(metadata.get("estimate", "")),
        "rafostrack_config": json.dumps(metadata.get("config", {}), sort_keys=True),
    }


def _encode_time(ds) -> None:
    ds["time"].encoding.update(units=TIME_UNITS, calendar="standard", dtype="float64")


def track_dataset(track: pd.DataFrame, info: FloatInfo, metadata: dict[str, Any]):
    """The track as an xarray Dataset following CF-1.8 discrete sampling geometry, one
    trajectory (`featureType = trajectory`, dimension `obs`, `trajectory` the float's id
    with `cf_role = trajectory_id`)."""
    import xarray as xr

    data: dict[str, Any] = {}
    for name, spec in TRACK.items():
        if name in ("float_id", "time") or name not in track:
            continue
        values = track[name].to_numpy()
        attrs = cf_attrs(spec)
        if name == "ambiguous":
            values = values.astype(np.int8)
            attrs.update(flag_values=np.array([0, 1], dtype=np.int8), flag_meanings="single_mode two_modes")
        elif name == "status":
            values = _status_flags(values)
            attrs.update(flag_values=np.arange(len(STATUSES), dtype=np.int8), flag_meanings=" ".join(STATUSES))
        else:
            values = values.astype(np.int32 if name == "n_signals" else np.float64)
        if name not in ("lat", "lon"):
            attrs["coordinates"] = "time lat lon"
        data[name] = (WINDOW_DIM, values, attrs)
    data["lat"][2].update(axis="Y")
    data["lon"][2].update(axis="X")
    coords = {
        "time": _time_coord(utc_naive(track["time"]), WINDOW_DIM),
        "lat": data.pop("lat"),
        "lon": data.pop("lon"),
    }
    data["trajectory"] = ((), info.float_id, {"cf_role": "trajectory_id", "long_name": "the float's id"})
    attrs = {**_global_attrs(info, metadata, "track"), "featureType": "trajectory"}
    ds = xr.Dataset(data, coords=coords, attrs=attrs)
    _encode_time(ds)
    _compress(ds)
    return ds


def _status_flags(statuses: np.ndarray) -> np.ndarray:
    """The track's statuses as their flag values (int8, `STATUSES`); a status without one is
    a bug upstream, not a user's mistake (ValueError)."""
    codes = pd.Index(STATUSES).get_indexer(statuses)
    if (codes < 0).any():
        raise ValueError(f"track status {statuses[int(np.argmax(codes < 0))]!r} has no flag value in {STATUSES}")
    return codes.astype(np.int8)


def _compress(ds) -> None:
    """zlib on every numeric array of `ds` (variable-length text cannot be compressed)."""
    for var in ds.variables.values():
        if var.ndim and var.dtype.kind in "biufM":
            var.encoding.update(ZLIB)


def window_index(label_times: np.ndarray, window_times: np.ndarray) -> np.ndarray:
    """Each label's window: the zero-based row of `window_times` equal to its time (int32).

    The labels and the track come from the same windows; a label time that is no window's
    is a bug upstream, not a user's mistake (ValueError)."""
    windows = pd.Index(window_times)
    if not windows.is_unique:
        raise ValueError("track times are not unique: a label's window is ambiguous")
    index = windows.get_indexer(label_times)
    if (index < 0).any():
        missing = pd.Timestamp(label_times[int(np.argmax(index < 0))])
        raise ValueError(f"labels at {missing.isoformat()} have no window in the track")
    return index.astype(np.int32)


def _label_column(values: pd.Series) -> tuple[np.ndarray, dict[str, Any]]:
    """A labels column as NetCDF values and encoding: integers int32, text with missing
    empty (`_FillValue = ""`), the rest float64 (NaN missing)."""
    if pd.api.types.is_integer_dtype(values.dtype):
        return values.to_numpy(dtype=np.int32), {}
    if pd.api.types.is_float_dtype(values.dtype):
        return values.to_numpy(dtype=np.float64), {}
    text = np.array(["" if pd.isna(v) else str(v) for v in values], dtype=str)
    return text, {"_FillValue": TEXT_FILL, "dtype": str}


def labels_dataset(
    labels: pd.DataFrame, track: pd.DataFrame, info: FloatInfo, metadata: dict[str, Any], track_file: str = "track.nc"
):
    """The labels table as an xarray Dataset: one row per TOA (dimension `label`), its
    window's `obs` row of `track_file` in `window_index` (module docstring)."""
    import xarray as xr

    times = utc_naive(labels["time"])
    index = window_index(times, utc_naive(track["time"]))
    data: dict[str, Any] = {}
    encoding: dict[str, dict[str, Any]] = {}
    for name, spec in LABELS.items():
        if name in ("float_id", "time") or name not in labels:
            continue
        values, encoding[name] = _label_column(labels[name])
        data[name] = (LABEL_DIM, values, cf_attrs(spec))
    data["window_index"] = (
        LABEL_DIM,
        index,
        {
            "long_name": f"zero-based row (dimension {WINDOW_DIM}) of the TOA's listening window in {track_file}",
            "instance_dimension": WINDOW_DIM,
        },
    )
    data["float_id"] = ((), info.float_id, cf_attrs(LABELS["float_id"]))
    attrs = {
        **_global_attrs(info, metadata, "labels of the arrival times (TOAs)"),
        "rafostrack_track_file": track_file,
        "comment": (
            f"one row per stored TOA (dimension {LABEL_DIM}); window_index is the row of its window in "
            f"{track_file} (dimension {WINDOW_DIM}): a CF indexed ragged array; beacon_id missing = clutter"
        ),
    }
    ds = xr.Dataset(data, coords={"time": _time_coord(times, LABEL_DIM)}, attrs=attrs)
    for name, enc in encoding.items():
        ds[name].encoding.update(enc)
    _encode_time(ds)
    _compress(ds)
    return ds


def write_netcdf(track: pd.DataFrame, info: FloatInfo, path: Path, metadata: dict[str, Any]) -> None:
    """`track.nc` (`track_dataset`), atomically."""
    ds = track_dataset(track, info, metadata)
    with atomic_path(path) as tmp:
        ds.to_netcdf(tmp, engine="h5netcdf", format="NETCDF4")


def write_labels_netcdf(
    labels: pd.DataFrame,
    track: pd.DataFrame,
    info: FloatInfo,
    path: Path,
    metadata: dict[str, Any],
    track_file: str = "track.nc",
) -> None:
    """`labels.nc` (`labels_dataset`) with the dimension `obs` of `track_file` declared, atomically."""
    import h5netcdf

    ds = labels_dataset(labels, track, info, metadata, track_file)
    with atomic_path(path) as tmp:
        ds.to_netcdf(tmp, engine="h5netcdf", format="NETCDF4")
        with h5netcdf.File(tmp, "a") as f:
            f.dimensions[WINDOW_DIM] = len(track)
