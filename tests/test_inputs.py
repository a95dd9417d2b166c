from __future__ import annotations

import numpy as np
import pytest

from rafostrack.config import load_config
from rafostrack.errors import InputError, Warnings
from rafostrack.inputs import read_arrivals, read_beacons, read_floats

BEACONS = "beacon_id,lat,lon,offset_s,start,end\nA,-58,-100,0,,\nB,-56,-95,600,2009-06-01,\n"
FLOATS = "float_id,launch_time,launch_lat,launch_lon,window_s,max_signals\nf1,2009-01-01T00:00:00Z,-57,-98,4000,3\n"


def _write(tmp_path, name, text, newline="\n", bom=False):
    path = tmp_path / name
    data = text.replace("\n", newline)
    path.write_bytes((b"\xef\xbb\xbf" if bom else b"") + data.encode())
    return path


def _mission(tmp_path, arrivals):
    beacons = read_beacons(_write(tmp_path, "beacons.csv", BEACONS))
    info = read_floats(_write(tmp_path, "floats.csv", FLOATS), load_config().model)["f1"]
    warnings = Warnings()
    record = read_arrivals(_write(tmp_path, "f1.csv", arrivals), info, beacons, warnings)
    return beacons, info, record, warnings


def test_reads_windows_sorted_in_any_row_order(tmp_path):
    _, _, record, warnings = _mission(
        tmp_path,
        "time,toa_s\n2009-01-03T00:00Z,300\n2009-01-02T00:00Z,200\n2009-01-02T00:00Z,100\n2009-01-04T00:00Z,\n",
    )
    assert [w.toa_s.tolist() for w in record.windows] == [[100.0, 200.0], [300.0], []]
    assert record.windows[0].time == np.datetime64("2009-01-02T00:00", "ns")
    assert len(warnings) == 0


def test_beacon_active_period(tmp_path):
    beacons = read_beacons(_write(tmp_path, "beacons.csv", BEACONS))
    assert beacons.active_at(np.datetime64("2009-01-01", "ns")).tolist() == [True, False]
    assert beacons.active_at(np.datetime64("2009-07-01", "ns")).tolist() == [True, True]


def test_recoverable_oddities_are_warned_not_silent(tmp_path):
    _, _, record, warnings = _mission(
        tmp_path,
        "time,toa_s\n"
        "2009-01-02T00:00Z,100\n2009-01-02T00:00Z,100\n"  # duplicate
        "2009-01-02T00:00Z,4500\n"  # beyond the 4000 s window
        "2009-01-03T00:00Z,1\n2009-01-03T00:00Z,2\n2009-01-03T00:00Z,3\n2009-01-03T00:00Z,4\n",  # > max 3
    )
    assert [w.toa_s.tolist() for w in record.windows] == [[100.0], [1.0, 2.0, 3.0]]
    text = " | ".join(warnings.messages)
    assert "duplicate" in text and "outside the window" in text and "max_signals=3" in text


def test_bom_and_crlf_are_accepted(tmp_path):
    beacons = read_beacons(_write(tmp_path, "beacons.csv", BEACONS, newline="\r\n", bom=True))
    assert list(beacons.beacon_id) == ["A", "B"]


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("beacon_id,lat,lng\nA,1,2\n", "missing required column 'lon' (did you mean 'lng'?)"),
        ("beacon_id;lat;lon\nA;1;2\n", "separated by ';'"),
        ("beacon_id,lat,lon\n", "header only"),
        ("", "file is empty"),
        ("beacon_id,lat,lon\nA,1,2\nA,3,4\n", "line 3: duplicate beacon_id 'A'"),
        ("beacon_id,lat,lon\nA,95,2\n", "line 2: field 'lat': expected a finite value in [-90, 90]"),
        ("beacon_id,lat,lon\nA,nan,2\n", "line 2: field 'lat'"),
        ("beacon_id,lat,lon\nA,x,2\n", "line 2: field 'lat': expected a number, got 'x'"),
        ("beacon_id,lat,lon,start\nA,1,2,yesterday\n", "line 2: field 'start': expected an ISO-8601 time"),
    ],
)
def test_bad_beacon_tables(tmp_path, text, needle):
    with pytest.raises(InputError) as err:
        read_beacons(_write(tmp_path, "beacons.csv", text))
    assert needle in str(err.value) and "beacons.csv" in str(err.value)


def test_missing_file(tmp_path):
    with pytest.raises(InputError, match="file not found"):
        read_beacons(tmp_path / "beacons.csv")


def test_window_before_launch_is_an_error(tmp_path):
    with pytest.raises(InputError, match="line 2: window at 2008-12-31T00:00:00Z is before the float's launch_time"):
        _mission(tmp_path, "time,toa_s\n2008-12-31T00:00Z,100\n")


def test_unknown_label(tmp_path):
    with pytest.raises(InputError, match="unknown beacon 'C'"):
        _mission(tmp_path, "time,toa_s,beacon_id\n2009-01-02T00:00Z,100,C\n")


def test_labels_are_kept_with_their_toas(tmp_path):
    _, _, record, _ = _mission(tmp_path, "time,toa_s,beacon_id\n2009-01-02T00:00Z,300,A\n2009-01-02T00:00Z,100,\n")
    assert record.windows[0].beacon_id == (None, "A")
    assert record.has_labels


def test_empty_optional_cells_take_defaults(tmp_path):
    beacons = read_beacons(
        _write(tmp_path, "beacons.csv", "beacon_id,lat,lon,offset_s,drift_s_per_day\nA,-58,-100,,\n")
    )
    assert beacons.offset_s.tolist() == [0.0] and beacons.drift_s_per_day.tolist() == [0.0]
    floats = "float_id,launch_time,launch_lat,launch_lon,window_s,max_signals\nf1,2009-01-01,-57,-98,,\n"
    info = read_floats(_write(tmp_path, "floats.csv", floats), load_config().model)["f1"]
    assert info.window_s == load_config().model.window_s and info.max_signals == load_config().model.max_signals
