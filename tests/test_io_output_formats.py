"""Outputs beyond Parquet: CSV, CF NetCDF, ARTOA .rfc; units in Parquet."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner

from rafostrack.cli import main
from rafostrack.io.columns import TABLES
from rafostrack.io.output_formats import RFC_COLUMNS, RFC_WIDTH, rafos_day, read_rfc

USER_GUIDE = Path(__file__).resolve().parents[1] / "docs" / "user-guide.md"


@pytest.fixture(scope="module")
def out(sim_mission_dir, tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("formats")
    args = ["track", str(sim_mission_dir / "sim1.csv"), "--out", str(root), "--no-plots", "--particles", "150"]
    result = CliRunner().invoke(main, [*args, "--format", "parquet,csv,netcdf,rfc"])
    assert result.exit_code == 0, result.output
    return root / "sim1"


def test_every_format_is_written(out):
    names = {p.name for p in out.iterdir()}
    assert {"track.parquet", "labels.parquet", "modes.parquet", "track.csv", "labels.csv", "modes.csv"} <= names
    assert {"track.nc", "sim1.rfc", "run.json"} <= names


def test_parquet_fields_carry_units(out):
    for table, columns in TABLES.items():
        schema = pq.read_schema(out / f"{table}.parquet")
        for field in schema:
            meta = {k.decode(): v.decode() for k, v in (field.metadata or {}).items()}
            assert meta.get("units") == columns[field.name].units, (table, field.name)
            assert meta.get("long_name")
    assert {k.decode(): v.decode() for k, v in pq.read_schema(out / "track.parquet").field("lat").metadata.items()}[
        "standard_name"
    ] == "latitude"


def test_csv_holds_the_parquet_values(out):
    for table in TABLES:
        a = pd.read_parquet(out / f"{table}.parquet")
        b = pd.read_csv(out / f"{table}.csv")
        assert list(a.columns) == list(b.columns)
        for col in a.columns:
            if col == "time":
                assert (pd.to_datetime(b[col], utc=True) == a[col]).all()
            elif pd.api.types.is_float_dtype(a[col]):
                np.testing.assert_allclose(b[col].to_numpy(float), a[col].to_numpy(float), rtol=1e-12, equal_nan=True)


def test_netcdf_is_a_cf_trajectory_readable_by_xarray(out):
    import xarray as xr

    track = pd.read_parquet(out / "track.parquet")
    with xr.open_dataset(out / "track.nc", engine="h5netcdf") as ds:
        assert ds.attrs["Conventions"] == "CF-1.8" and ds.attrs["featureType"] == "trajectory"
        assert ds["trajectory"].attrs["cf_role"] == "trajectory_id" and str(ds["trajectory"].values) == "sim1"
        assert ds["time"].attrs["standard_name"] == "time" and ds["time"].attrs["axis"] == "T"
        assert ds["time"].encoding["units"].startswith("seconds since 1970-01-01")
        assert (ds["lat"].attrs["units"], ds["lat"].attrs["standard_name"]) == ("degrees_north", "latitude")
        assert (ds["lon"].attrs["units"], ds["lon"].attrs["standard_name"]) == ("degrees_east", "longitude")
        for name, var in ds.data_vars.items():
            if name == "trajectory":
                continue
            assert var.dims == ("obs",) and var.encoding.get("coordinates") == "time lat lon", name
            assert "units" in var.attrs or "flag_values" in var.attrs or name == "status", name
            assert var.attrs["long_name"]
        np.testing.assert_array_equal(ds["time"].values, track["time"].dt.tz_localize(None).to_numpy())
        np.testing.assert_allclose(ds["lat"].values, track["lat"])
        np.testing.assert_allclose(ds["sd_km"].values, track["sd_km"])
        assert list(ds["ambiguous"].values.astype(bool)) == list(track["ambiguous"])


def test_rfc_fixed_width_columns(out):
    text = (out / "sim1.rfc").read_text().splitlines()
    header = [line for line in text if line.startswith("**")]
    body = [line for line in text if not line.startswith("**")]
    assert len(header) >= 3 and all(len(line) == RFC_WIDTH * len(RFC_COLUMNS) for line in body)
    assert "degC" in header[2] and "cm/s" in header[2] and "mm/s" in header[2]
    rows = read_rfc(out / "sim1.rfc")
    track = pd.read_parquet(out / "track.parquet")
    assert len(rows) == len(track) and list(rows["LineNum"]) == list(range(1, len(track) + 1))
    np.testing.assert_allclose(rows["Lat"], track["lat"], atol=1e-5)
    np.testing.assert_allclose(rows["Lon"], track["lon"], atol=1e-5)
    days = rafos_day(track["time"].dt.tz_localize(None).to_numpy())
    np.testing.assert_allclose(rows["RafosDay"], days, atol=1e-4)
    # RAFOS day = Julian day - 2440000: 2000-01-01T12:00Z is JD 2451545.0
    assert rafos_day(np.array(["2000-01-01T12:00"], dtype="datetime64[ns]"))[0] == pytest.approx(11545.0)
    assert (rows["Temp"] == -9.99).all() and (rows["Pres"] == -999).all() and (rows["W"] == 999).all()
    speed = np.hypot(rows["U"], rows["V"])  # cm/s; a float drifts a few km/day = a few cm/s
    assert 0 < np.median(speed) < 100


def test_unknown_format_is_one_line(sim_mission_dir, tmp_path):
    args = ["track", str(sim_mission_dir / "sim1.csv"), "--out", str(tmp_path), "--format", "parquet,netcfd"]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 2
    assert "unknown output format 'netcfd' (did you mean 'netcdf'?)" in result.output


def test_user_guide_documents_every_output_column_with_units():
    text = USER_GUIDE.read_text(encoding="utf-8")
    section = text[text.index("### Output columns") :]
    section = section[: section.index("\n## ")]
    for table, columns in TABLES.items():
        for name, spec in columns.items():
            row = re.search(rf"^\| `{table}` \| `{name}` \| ([^|]*) \|", section, re.MULTILINE)
            assert row, f"{table}.{name} not in the user guide's Output columns"
            assert row.group(1).strip() == (f"`{spec.units}`" if spec.units else "—"), (table, name)
