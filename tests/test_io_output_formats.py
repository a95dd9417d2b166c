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
from rafostrack.domain import FloatInfo
from rafostrack.io.columns import LABELS, TABLES
from rafostrack.io.netcdf import write_labels_netcdf
from rafostrack.io.output_formats import RFC_COLUMNS, RFC_WIDTH, rafos_day, read_rfc, write_estimate
from rafostrack.summaries.estimates import LABEL_COLUMNS, TRACK_COLUMNS, _frame

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
    assert {"track.nc", "labels.nc", "sim1.rfc", "run.json"} <= names


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
            assert "units" in var.attrs or "flag_values" in var.attrs, name
            assert var.attrs["long_name"]
        np.testing.assert_array_equal(ds["time"].values, track["time"].dt.tz_localize(None).to_numpy())
        np.testing.assert_allclose(ds["lat"].values, track["lat"])
        np.testing.assert_allclose(ds["sd_km"].values, track["sd_km"])
        assert list(ds["ambiguous"].values.astype(bool)) == list(track["ambiguous"])


def _labels_from_netcdf(ds) -> pd.DataFrame:
    """labels.nc as the labels table: the frame xarray gives, times in UTC, NaN text as None."""
    frame = ds.to_dataframe().reset_index(drop=True)
    frame["time"] = frame["time"].dt.tz_localize("UTC")
    frame["beacon_id"] = frame["beacon_id"].astype(object).where(frame["beacon_id"].notna(), None)
    return frame[list(LABEL_COLUMNS)]


def _as_written(labels: pd.DataFrame) -> pd.DataFrame:
    """The labels table as Parquet holds it: UTC times, rank int32 as NetCDF stores it."""
    frame = labels.copy()
    frame["time"] = pd.to_datetime(frame["time"], utc=True).dt.as_unit("ns")
    frame["beacon_id"] = frame["beacon_id"].astype(object).where(frame["beacon_id"].notna(), None)
    return frame.astype({"rank": "int32"})[list(LABEL_COLUMNS)]


def test_netcdf_labels_read_back_equal_the_labels_table(out):
    """labels.nc holds labels.parquet: every column under its name with the Parquet field's
    units and long_name, clutter (null beacon_id) missing, times UTC."""
    import h5netcdf.legacyapi
    import xarray as xr

    labels = pd.read_parquet(out / "labels.parquet")
    assert labels["beacon_id"].isna().any() and labels["beacon_id"].notna().any()
    with xr.open_dataset(out / "labels.nc") as ds:
        assert ds.attrs["Conventions"] == "CF-1.8" and "featureType" not in ds.attrs
        assert ds.attrs["rafostrack_track_file"] == "track.nc" and ds.attrs["rafostrack_estimate"] == "smoothed"
        assert set(ds.dims) == {"label"}
        pd.testing.assert_frame_equal(_labels_from_netcdf(ds), _as_written(labels), check_dtype=False)
        schema = pq.read_schema(out / "labels.parquet")
        for name in LABELS:
            meta = {k.decode(): v.decode() for k, v in (schema.field(name).metadata or {}).items()}
            attrs = ds[name].attrs
            assert attrs["long_name"] == meta["long_name"], name
            if name != "time":  # time's units are the encoding's
                assert attrs.get("units", "") == meta["units"], name
        assert ds["time"].attrs["standard_name"] == "time"
        assert ds["time"].encoding["units"].startswith("seconds since 1970-01-01")
    with h5netcdf.legacyapi.Dataset(out / "labels.nc", "r") as nc:  # the netCDF4 library's interface
        assert nc.dimensions["obs"].size == len(pd.read_parquet(out / "track.parquet"))
        assert nc.dimensions["label"].size == len(labels)
        assert nc.variables["window_index"].getncattr("instance_dimension") == "obs"
        assert nc.variables["beacon_id"].getncattr("_FillValue") == ""
        assert np.isnan(nc.variables["prob"].getncattr("_FillValue"))
        raw = [b.decode() if isinstance(b, bytes) else b for b in nc.variables["beacon_id"][:]]
        assert raw == list(labels["beacon_id"].fillna(""))


def test_netcdf_label_window_index_links_each_toa_to_its_window_in_track_nc(out):
    import xarray as xr

    with xr.open_dataset(out / "track.nc") as track, xr.open_dataset(out / "labels.nc") as labels:
        index = labels["window_index"].values
        assert labels["window_index"].attrs["instance_dimension"] == "obs"
        np.testing.assert_array_equal(track["time"].values[index], labels["time"].values)
        # the windows' TOA counts: each window of track.nc has n_signals labels
        counts = np.bincount(index, minlength=track.sizes["obs"])
        np.testing.assert_array_equal(counts, track["n_signals"].values)


def _info(float_id: str = "f1") -> FloatInfo:
    nat = np.datetime64("NaT", "ns")
    return FloatInfo(
        float_id, np.datetime64("1989-12-31", "ns"), -57.0, -98.0, nat, np.nan, np.nan, 0.0, 0.0, 4200.0, 4
    )


def _tables(label_rows: list[tuple]) -> dict[str, pd.DataFrame]:
    """Three windows (2, 0 and 1 TOAs stored) and the labels `label_rows` of float f1."""
    times = pd.to_datetime(["1990-01-01T00:00", "1990-01-02T06:00", "1990-01-03T00:00"])
    rows = [
        ("f1", t, -57.0 + k, -98.0, 1.0, 1.0, 1.0, 0.0, 100.0, n, -1.0, False, np.nan, "ok")
        for k, (t, n) in enumerate(zip(times, (2, 0, 1), strict=True))
    ]
    return {
        "track": _frame(rows, TRACK_COLUMNS, {"n_signals": "int64", "ambiguous": "bool"}, ("status",)),
        "labels": _frame(label_rows, LABEL_COLUMNS, {"rank": "int64"}, ("beacon_id",)),
        "modes": pd.DataFrame(),
    }


def _statuses(ds) -> list[str]:
    """track.nc's `status` read back through its CF flags."""
    meanings = dict(zip(ds["status"].attrs["flag_values"], ds["status"].attrs["flag_meanings"].split(), strict=True))
    return [meanings[v] for v in ds["status"].values.tolist()]


def test_netcdf_status_is_cf_flags_and_every_array_is_compressed(out):
    """`status` was text; it is an int8 CF flag variable, and each numeric array of both files
    is zlib-compressed (variable-length text cannot be)."""
    import h5py
    import xarray as xr

    track = pd.read_parquet(out / "track.parquet")
    with xr.open_dataset(out / "track.nc") as ds:
        assert ds["status"].dtype == np.int8 and ds["status"].attrs["flag_values"].tolist() == [0, 1, 2, 3]
        assert ds["status"].attrs["flag_meanings"] == "ok ambiguous unsupported recovered"
        assert _statuses(ds) == track["status"].tolist()
    for name in ("track.nc", "labels.nc"):
        with h5py.File(out / name, "r") as f:
            arrays = [k for k, v in f.items() if v.shape and v.dtype.kind in "biuf" and k not in ("obs", "label")]
            assert len(arrays) >= 6 and all(f[k].compression == "gzip" for k in arrays), name


def test_netcdf_every_status_round_trips_and_an_unknown_one_is_refused(tmp_path):
    import xarray as xr

    tables = _tables([])
    statuses = ["recovered", "unsupported", "ambiguous"]
    tables["track"]["status"] = statuses
    write_estimate(tmp_path, tables, _info(), ("netcdf",), {})
    with xr.open_dataset(tmp_path / "track.nc") as ds:
        assert _statuses(ds) == statuses and ds["status"].values.tolist() == [3, 2, 1]
    tables["track"]["status"] = ["ok", "lost", "ok"]
    with pytest.raises(ValueError, match="track status 'lost' has no flag value"):
        write_estimate(tmp_path / "bad", tables, _info(), ("netcdf",), {})


def test_netcdf_labels_keep_missing_values_and_name_the_filtered_track(tmp_path):
    """A clutter TOA's beacon_id and a NaN probability come back missing; the filtered
    estimate's labels point at track_filtered.nc."""
    import xarray as xr

    t = pd.to_datetime(["1990-01-01", "1990-01-03"])
    tables = _tables(
        [("f1", t[0], 1, 100.5, "B1", 0.9, 0.1), ("f1", t[0], 2, 700.0, None, 0.8, 0.8),
         ("f1", t[1], 1, 50.25, "US1-3", np.nan, 0.0)]
    )  # fmt: skip
    written = write_estimate(tmp_path, tables, _info(), ("netcdf",), {"estimate": "filtered"}, "_filtered")
    assert [p.name for p in written] == ["track_filtered.nc", "labels_filtered.nc"]
    with xr.open_dataset(tmp_path / "labels_filtered.nc") as ds:
        assert ds.attrs["rafostrack_track_file"] == "track_filtered.nc"
        assert list(ds["window_index"].values) == [0, 0, 2]
        pd.testing.assert_frame_equal(_labels_from_netcdf(ds), _as_written(tables["labels"]), check_dtype=False)
        assert ds["beacon_id"].isnull().values.tolist() == [False, True, False]
        assert np.isnan(ds["prob"].values[2])


def test_netcdf_labels_times_are_utc_whatever_zone_the_table_has(tmp_path):
    import xarray as xr

    t = pd.Timestamp("1990-01-03T00:00")
    tables = _tables([("f1", t.tz_localize("UTC").tz_convert("Etc/GMT+3"), 1, 50.0, "B1", 0.9, 0.1)])
    write_labels_netcdf(tables["labels"], tables["track"], _info(), tmp_path / "labels.nc", {})
    with xr.open_dataset(tmp_path / "labels.nc") as ds:
        assert ds["time"].values.tolist() == [t.to_datetime64().astype("datetime64[ns]").item()]
        assert list(ds["window_index"].values) == [2]


def test_netcdf_empty_labels_table_writes_a_valid_file(tmp_path):
    import h5py
    import xarray as xr

    tables = _tables([])
    write_labels_netcdf(tables["labels"], tables["track"], _info(), tmp_path / "labels.nc", {})
    with xr.open_dataset(tmp_path / "labels.nc") as ds:
        assert ds.sizes["label"] == 0 and str(ds["float_id"].values) == "f1"
        assert set(LABELS) <= set(ds.variables) | {"float_id"}
        assert ds["toa_s"].attrs["units"] == "s" and ds["window_index"].dtype == np.int32
        assert _labels_from_netcdf(ds).empty
    with h5py.File(tmp_path / "labels.nc", "r") as f:  # text stays text: a NetCDF-4 string variable
        assert h5py.check_string_dtype(f["beacon_id"].dtype) is not None and f["obs"].shape == (3,)


def test_netcdf_label_without_a_window_in_the_track_is_refused(tmp_path):
    tables = _tables([("f1", pd.Timestamp("1990-01-02"), 1, 50.0, "B1", 0.9, 0.1)])  # no window at 00:00
    with pytest.raises(ValueError, match="labels at 1990-01-02T00:00:00 have no window in the track"):
        write_labels_netcdf(tables["labels"], tables["track"], _info(), tmp_path / "labels.nc", {})
    assert not list(tmp_path.iterdir())


def test_netcdf_labels_are_written_atomically(tmp_path, monkeypatch):
    """A write that fails once the file's bytes are out leaves the previous labels.nc whole
    and no temporary file behind."""
    import xarray as xr

    t = pd.Timestamp("1990-01-01")
    tables = _tables([("f1", t, 1, 100.0, "B1", 0.9, 0.1), ("f1", t, 2, 700.0, None, 0.8, 0.8)])
    path = tmp_path / "labels.nc"
    write_labels_netcdf(tables["labels"], tables["track"], _info(), path, {})
    before = path.read_bytes()
    original = xr.Dataset.to_netcdf

    def write_then_fail(self, target, *args, **kwargs):
        original(self, target, *args, **kwargs)
        raise OSError("disk full")

    monkeypatch.setattr(xr.Dataset, "to_netcdf", write_then_fail)
    changed = _tables([("f1", t, 1, 123.0, "B2", 0.7, 0.3)])
    with pytest.raises(OSError, match="disk full"):
        write_labels_netcdf(changed["labels"], changed["track"], _info(), path, {})
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["labels.nc"]


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
