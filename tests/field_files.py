"""Writers of field-format files in their real layouts, for the reader tests (not package code:
the package reads these formats, it does not write them)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from rafostrack.io.argo_aux import ARGO_EPOCH
from rafostrack.io.output_formats import RAFOS_DAY_EPOCH


def arrivals_table(csv_path: Path) -> pd.DataFrame:
    """A CSV arrival file: time (datetime64), toa_s (NaN = empty window), beacon_id ('' = clutter), quality."""
    frame = pd.read_csv(csv_path, dtype={"beacon_id": str}, keep_default_na=False, na_values={"toa_s": [""]})
    frame["time"] = pd.to_datetime(frame["time"], utc=True).dt.tz_localize(None)
    frame["toa_s"] = pd.to_numeric(frame["toa_s"])
    return frame


def write_dimes_mat(frame: pd.DataFrame, sources: list[str], path: Path, v73: bool = False) -> None:
    """TOA, TOA_SEL, TOA_DATE (RAFOS days), SOSOREF: one entry per TOA (MATLAB column vectors)."""
    index = {s: k + 1 for k, s in enumerate(sources)}
    toa = frame["toa_s"].to_numpy(float)[:, None]
    sel = np.array([index.get(b, 0) for b in frame["beacon_id"]], dtype=float)[:, None]
    day = ((frame["time"].to_numpy("datetime64[ns]") - RAFOS_DAY_EPOCH) / np.timedelta64(1, "D"))[:, None]
    if not v73:
        from scipy.io import savemat

        names = np.empty((len(sources), 1), dtype=object)
        names[:, 0] = sources
        savemat(path, {"TOA": toa, "TOA_SEL": sel, "TOA_DATE": day, "SOSOREF": names})
        return
    import h5py

    with h5py.File(path, "w") as f:  # MATLAB v7.3: transposed arrays, char as uint16, cells as references
        for name, value in (("TOA", toa), ("TOA_SEL", sel), ("TOA_DATE", day)):
            f.create_dataset(name, data=value.T).attrs["MATLAB_class"] = np.bytes_("double")
        refs = f.create_group("#refs#")
        ref_list = []
        for k, s in enumerate(sources):
            ds = refs.create_dataset(f"s{k}", data=np.array([[ord(c)] for c in s], dtype=np.uint16))
            ds.attrs["MATLAB_class"] = np.bytes_("char")
            ref_list.append(ds.ref)
        cell = f.create_dataset("SOSOREF", data=np.array([ref_list], dtype=h5py.ref_dtype))
        cell.attrs["MATLAB_class"] = np.bytes_("cell")


def write_argo_aux(frame: pd.DataFrame, path: Path, slots: int = 6) -> None:
    """N_MEASUREMENT records: one per window (TOA/COR fill -1, up to `slots`), plus a surface
    fix record without RAFOS data, as in an Argo auxiliary trajectory file."""
    import xarray as xr

    windows = list(frame.groupby("time", sort=True))
    n = len(windows) + 1
    toa = np.full((n, slots), -1.0)
    cor = np.full((n, slots), -1.0)
    juld = np.full(n, np.nan)
    rtc = np.full(n, np.nan)
    for k, (t, g) in enumerate(windows):
        values = g["toa_s"].dropna().to_numpy(float)
        toa[k, : len(values)] = values
        cor[k, : len(values)] = g.loc[g["toa_s"].notna(), "quality"].to_numpy(float)
        juld[k] = (np.datetime64(t, "ns") - ARGO_EPOCH) / np.timedelta64(1, "D")
        rtc[k] = juld[k] + 1.5 / 86400  # the float's clock, a little fast
    juld[-1] = juld[-2] + 0.5  # the surface fix record
    ds = xr.Dataset(
        {
            "JULD": ("N_MEASUREMENT", juld, {"units": "days since 1950-01-01 00:00:00 UTC"}),
            "RAFOS_RTC_TIME": ("N_MEASUREMENT", rtc),
            "RAFOS_STATUS": ("N_MEASUREMENT", np.zeros(n, dtype=np.int8)),
            "TOA": (("N_MEASUREMENT", "N_RAFOS"), toa, {"units": "second"}),
            "COR": (("N_MEASUREMENT", "N_RAFOS"), cor),
        }
    )
    fill = {"_FillValue": 999999.0}
    ds.to_netcdf(path, engine="h5netcdf", encoding={"JULD": fill, "RAFOS_RTC_TIME": fill})


def write_soso(beacons_csv: Path, path: Path) -> None:
    frame = pd.read_csv(beacons_csv, dtype=str, keep_default_na=False)
    lines = ["% name lat lon begin end offset_s drift_s_per_day"]
    for _, r in frame.iterrows():
        lines.append(
            f"{r.beacon_id} {r.lat} {r.lon} {r.get('start') or '-'} {r.get('end') or '-'} "
            f"{r.get('offset_s') or 0} {r.get('drift_s_per_day') or 0}"
        )
    path.write_text("\n".join(lines) + "\n")


OPTIONS = {"particles": 100, "calibrate_enabled": False, "seed": 5}
_BASELINE: dict[str, object] = {}


def mission_with_quality(sim_mission_dir: Path, dest: Path) -> Path:
    """A copy of the simulated mission whose arrival file has a correlation height per TOA."""
    import shutil

    shutil.copytree(sim_mission_dir, dest)
    frame = pd.read_csv(dest / "sim1.csv", dtype=str, keep_default_na=False)
    rng = np.random.default_rng(1)
    heights = np.round(rng.uniform(10, 90, len(frame)), 1)
    frame["quality"] = [f"{q:g}" if t else "" for q, t in zip(heights, frame["toa_s"], strict=True)]
    frame.to_csv(dest / "sim1.csv", index=False)
    return dest


def csv_run(mission: Path):
    """The CSV mission tracked once per session (the round trips compare with it)."""
    import rafostrack

    key = str(mission)
    if key not in _BASELINE:
        _BASELINE[key] = rafostrack.track(mission / "sim1.csv", **OPTIONS)
    return _BASELINE[key]
