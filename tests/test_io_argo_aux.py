"""Argo auxiliary trajectory NetCDF reader (`rafostrack.io.argo_aux`)."""

from __future__ import annotations

import shutil

import numpy as np
import pandas as pd
import pytest
from field_files import OPTIONS, arrivals_table, csv_run, write_argo_aux

import rafostrack
from rafostrack.config import load_config
from rafostrack.errors import InputError, Warnings
from rafostrack.io import read_arrivals, read_beacons, read_floats, reader_for


def _loaded(mission):
    beacons = read_beacons(mission / "beacons.csv")
    info = read_floats(mission / "floats.csv", load_config().model)["sim1"]
    return beacons, info


def test_round_trip_equals_the_csv_run(quality_mission, tmp_path):
    mission = tmp_path / "m"
    shutil.copytree(quality_mission, mission)
    nc = mission / "sim1_Rtraj_aux.nc"
    write_argo_aux(arrivals_table(mission / "sim1.csv"), nc)
    (mission / "sim1.csv").unlink()
    assert reader_for("arrivals", nc).format == "argo-aux"
    beacons, info = _loaded(mission)
    from_nc = read_arrivals(nc, info, beacons, Warnings())
    from_csv = read_arrivals(quality_mission / "sim1.csv", info, beacons, Warnings())
    assert len(from_nc.windows) == len(from_csv.windows)
    for a, b in zip(from_nc.windows, from_csv.windows, strict=True):
        assert a.time == b.time
        np.testing.assert_allclose(a.toa_s, b.toa_s, atol=1e-6)
        np.testing.assert_allclose(a.quality, b.quality, atol=1e-6)  # COR becomes quality
    run = rafostrack.track(nc, **OPTIONS)
    base = csv_run(quality_mission)
    assert run.float_id == "sim1"
    pd.testing.assert_frame_equal(run.track, base.track)
    pd.testing.assert_frame_equal(run.labels, base.labels)


def test_layout_errors_are_one_line(quality_mission, tmp_path):
    import xarray as xr

    beacons, info = _loaded(quality_mission)
    path = tmp_path / "x_Rtraj_aux.nc"
    xr.Dataset({"JULD": ("N_MEASUREMENT", np.array([22000.0]))}).to_netcdf(path, engine="h5netcdf")
    with pytest.raises(InputError, match=r"missing variable\(s\) TOA, COR, RAFOS_RTC_TIME"):
        read_arrivals(path, info, beacons, Warnings())
    path.write_bytes(b"not a netcdf file")
    with pytest.raises(InputError, match="cannot read as NetCDF-4"):
        read_arrivals(path, info, beacons, Warnings())
