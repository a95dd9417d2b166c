"""Argo auxiliary trajectory NetCDF (`<platform>_Rtraj_aux.nc`): a RAFOS float's arrival times.

Read with xarray (h5netcdf). Per measurement record (dimension `N_MEASUREMENT`): `JULD`
(days since 1950-01-01T00:00Z, the Argo reference date: the window's time), `TOA` (s after
the window opens, up to 6 per record; fill -1), `COR` (the correlation height of each TOA,
our `quality`), `RAFOS_RTC_TIME` (the float's clock time of the window) and `RAFOS_STATUS`.
A record is a listening window when its `RAFOS_RTC_TIME` is set (other measurement
records, e.g. surface fixes, are skipped); a window whose TOAs are all fill stored nothing.
`RAFOS_STATUS` is read but not interpreted: its codes are not publicly documented. The
float id is the file name's platform number (`6901234_Rtraj_aux.nc` -> `6901234`).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ..domain import ArrivalRecord, BeaconTable, FloatInfo
from ..errors import InputError, Warnings
from .csv_table import require_file
from .records import build_record

ARGO_EPOCH = np.datetime64("1950-01-01T00:00:00", "ns")
TOA_FILL = -1.0
REQUIRED = ("JULD", "TOA", "COR", "RAFOS_RTC_TIME")
_NAME = re.compile(r"^(?P<platform>.+)_Rtraj_aux\.nc$", re.IGNORECASE)


def matches(path: Path) -> bool:
    return bool(_NAME.match(Path(path).name))


def float_id(path: Path) -> str:
    m = _NAME.match(Path(path).name)
    return m.group("platform") if m else Path(path).stem


def _days(values: np.ndarray) -> np.ndarray:
    """Days since the Argo epoch as datetime64 (NaN / fill -> NaT)."""
    seconds = np.round(np.asarray(values, dtype=float) * 86400.0 * 1e3)  # to the millisecond
    out = np.full(seconds.shape, np.datetime64("NaT", "ns"))
    ok = np.isfinite(seconds)
    out[ok] = ARGO_EPOCH + seconds[ok].astype(np.int64) * np.timedelta64(1, "ms")
    return out


def read_arrivals(path: Path, info: FloatInfo, beacons: BeaconTable, warnings: Warnings) -> ArrivalRecord:
    """The float's windows from an auxiliary trajectory file (module docstring)."""
    import xarray as xr

    path = Path(path)
    require_file(path, "expected an Argo auxiliary trajectory NetCDF file")
    try:
        ds = xr.open_dataset(path, engine="h5netcdf", decode_times=False, mask_and_scale=True)
    except (OSError, ValueError) as exc:
        raise InputError(f"{path}: cannot read as NetCDF-4 ({' '.join(str(exc).split())})") from None
    with ds:
        missing = [v for v in REQUIRED if v not in ds.variables]
        if missing:
            raise InputError(
                f"{path}: missing variable(s) {', '.join(missing)}; expected an Argo auxiliary trajectory file with "
                f"{', '.join(REQUIRED)}"
            )
        toa = np.asarray(ds["TOA"].values, dtype=float)
        cor = np.asarray(ds["COR"].values, dtype=float)
        juld = np.asarray(ds["JULD"].values, dtype=float)
        rtc = np.asarray(ds["RAFOS_RTC_TIME"].values, dtype=float)
    if toa.ndim != 2 or cor.shape != toa.shape or juld.shape != (toa.shape[0],) or rtc.shape != juld.shape:
        raise InputError(
            f"{path}: variable shapes TOA {toa.shape}, COR {cor.shape}, JULD {juld.shape}, RAFOS_RTC_TIME "
            f"{rtc.shape}; expected TOA and COR (N_MEASUREMENT, slots) and the others (N_MEASUREMENT,)"
        )
    window = np.isfinite(rtc)
    if not window.any():
        raise InputError(f"{path}: no RAFOS window (RAFOS_RTC_TIME is empty in every record); expected some")
    records = np.flatnonzero(window)
    times = _days(juld[records])
    if np.isnat(times).any():
        k = int(records[np.argmax(np.isnat(times))])
        raise InputError(f"{path}: measurement {k}: JULD is empty for a RAFOS window; expected its time")
    toa, cor = toa[records], cor[records]
    toa = np.where(toa == TOA_FILL, np.nan, toa)
    n = toa.shape[0]
    stored = np.isfinite(toa)
    empty = ~stored.any(axis=1)
    rows = np.concatenate([np.repeat(np.arange(n), stored.sum(axis=1)), np.flatnonzero(empty)])
    values = np.concatenate([toa[stored], np.full(int(empty.sum()), np.nan)])
    quality = np.concatenate(
        [np.where(np.isfinite(cor[stored]), cor[stored], np.nan), np.full(int(empty.sum()), np.nan)]
    )
    return build_record(
        path,
        info,
        beacons,
        times[rows],
        values,
        warnings,
        quality=quality,
        where=lambda i: f"measurement {records[rows[i]]}",
    )
