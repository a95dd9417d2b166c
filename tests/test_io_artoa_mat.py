"""DIMES / ARTOA interim MATLAB reader (`rafostrack.io.artoa_mat`), v5 and v7.3 files."""

from __future__ import annotations

import shutil

import numpy as np
import pandas as pd
import pytest
from field_files import OPTIONS, arrivals_table, csv_run, write_dimes_mat

import rafostrack
from rafostrack.config import load_config
from rafostrack.errors import InputError, Warnings
from rafostrack.io import float_id_of, read_arrivals, read_beacons, read_floats, reader_for


@pytest.mark.parametrize("v73", [False, True])
def test_round_trip_equals_the_csv_run(quality_mission, tmp_path, v73):
    mission = tmp_path / "m"
    shutil.copytree(quality_mission, mission)
    sources = [str(b) for b in read_beacons(mission / "beacons.csv").beacon_id]
    mat = mission / "rf0001toa.mat"
    write_dimes_mat(arrivals_table(mission / "sim1.csv"), sources, mat, v73=v73)
    (mission / "sim1.csv").unlink()
    assert reader_for("arrivals", mat).format == "artoa-mat" and float_id_of(mat) == "1"
    beacons = read_beacons(mission / "beacons.csv")
    info = read_floats(mission / "floats.csv", load_config().model)["sim1"]
    from_mat = read_arrivals(mat, info, beacons, Warnings())
    from_csv = read_arrivals(quality_mission / "sim1.csv", info, beacons, Warnings())
    for a, b in zip(from_mat.windows, from_csv.windows, strict=True):
        assert abs((a.time - b.time) / np.timedelta64(1, "ms")) <= 1
        np.testing.assert_allclose(a.toa_s, b.toa_s)
        assert a.beacon_id == b.beacon_id  # TOA_SEL -> SOSOREF names -> beacon ids; 0 -> clutter
    run = rafostrack.track(mat, **OPTIONS)
    base = csv_run(quality_mission)
    assert run.float_id == "sim1"  # rf0001toa.mat found float 'sim1' by its number
    pd.testing.assert_frame_equal(run.track, base.track)
    pd.testing.assert_frame_equal(run.labels, base.labels)


def test_window_rows_layout_and_errors(quality_mission, tmp_path):
    from scipy.io import savemat

    beacons = read_beacons(quality_mission / "beacons.csv")
    info = read_floats(quality_mission / "floats.csv", load_config().model)["sim1"]
    day0 = (info.launch_time - np.datetime64("1968-05-23T12:00", "ns")) / np.timedelta64(1, "D")
    names = np.empty((2, 1), dtype=object)
    names[:, 0] = [str(beacons.beacon_id[0]), str(beacons.beacon_id[1])]
    path = tmp_path / "f.itm"
    toa = np.array([[500.0, 900.0, np.nan], [np.nan, np.nan, np.nan]])
    sel = np.array([[1, 0, 0], [0, 0, 0]], dtype=float)
    savemat(path, {"TOA": toa, "TOA_SEL": sel, "TOA_DATE": np.array([day0 + 1, day0 + 2]), "SOSOREF": names})
    with open(path, "rb") as fh:
        header = fh.read(4)
    assert header  # a MATLAB 5 file, read by scipy.io under the .itm name
    record = read_arrivals(path, info, beacons, Warnings())
    assert [w.n_signals for w in record.windows] == [2, 0]  # the second window stored nothing
    assert record.windows[0].beacon_id == (str(beacons.beacon_id[0]), None)
    names[1, 0] = "NOPE"
    savemat(path, {"TOA": toa, "TOA_SEL": sel, "TOA_DATE": np.array([day0 + 1, day0 + 2]), "SOSOREF": names})
    with pytest.raises(InputError, match="SOSOREF source 'NOPE' is not in the beacon table"):
        read_arrivals(path, info, beacons, Warnings())
    savemat(path, {"TOA": toa, "TOA_SEL": sel[:1], "TOA_DATE": np.array([day0]), "SOSOREF": names})
    with pytest.raises(InputError, match="differ in shape"):
        read_arrivals(path, info, beacons, Warnings())


def test_warnings_are_the_csv_readers_naming_the_toa_entry(quality_mission, tmp_path):
    from scipy.io import savemat

    beacons = read_beacons(quality_mission / "beacons.csv")
    info = read_floats(quality_mission / "floats.csv", load_config().model)["sim1"]
    day0 = (info.launch_time - np.datetime64("1968-05-23T12:00", "ns")) / np.timedelta64(1, "D")
    names = np.empty((1, 1), dtype=object)
    names[0, 0] = str(beacons.beacon_id[0])
    path = tmp_path / "f.itm"
    toa = np.array([[500.0, info.window_s + 10.0, 500.0]])  # one beyond the window, one repeated
    savemat(path, {"TOA": toa, "TOA_SEL": np.ones_like(toa), "TOA_DATE": np.array([day0 + 1]), "SOSOREF": names})
    warnings = Warnings()
    record = read_arrivals(path, info, beacons, warnings)
    assert [w.toa_s.tolist() for w in record.windows] == [[500.0]]
    assert f"{path}: 1 duplicate entry(s) (same time and TOA) dropped (first at TOA entry 3)" in warnings.messages
    assert (
        f"{path}: 1 TOA(s) outside the window [0, {info.window_s:g}] s dropped (0 negative, 1 beyond window_s; "
        f"first at TOA entry 2: TOA = {info.window_s + 10.0:g})"
    ) in warnings.messages


@pytest.mark.parametrize(
    ("content", "needle"),
    [
        (b"", "file is empty (0 bytes); expected an ARTOA interim MATLAB file with TOA, TOA_SEL, TOA_DATE, SOSOREF"),
        (b"MATLAB 5.0 MAT-file", "cannot read as a MATLAB file (Mat file appears to be truncated)"),
        (b"\x89HDF\r\n\x1a\n", "cannot read as a MATLAB v7.3 (HDF5) file"),
    ],
)
def test_an_empty_or_truncated_file_is_one_line_naming_it(quality_mission, tmp_path, content, needle):
    """A 0-byte or cut-off .mat was an internal error (MatReadError, exit 1), not an input error."""
    from click.testing import CliRunner

    from rafostrack.cli import main

    mission = tmp_path / "m"
    shutil.copytree(quality_mission, mission)
    mat = mission / "rf0001toa.mat"
    mat.write_bytes(content)
    beacons = read_beacons(mission / "beacons.csv")
    info = read_floats(mission / "floats.csv", load_config().model)["sim1"]
    with pytest.raises(InputError) as caught:
        read_arrivals(mat, info, beacons, Warnings())
    assert str(caught.value).startswith(f"{mat}: {needle}")
    result = CliRunner().invoke(main, ["track", str(mat), "--input-format", "artoa-mat", "--out", str(tmp_path / "o")])
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"rafostrack: error: {mat}: {needle}"), result.output
