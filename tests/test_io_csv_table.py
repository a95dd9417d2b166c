"""Strict CSV reading (`rafostrack.io.csv_table`): structure errors name the file and line.

Rows of the "Input checks" table of docs/user-guide.md; `pytest -m reliability` runs them with the other
hardening tests.
"""

from __future__ import annotations

import pytest
from support import (
    ARRIVALS,
    BEACONS,
    FLOATS,
    MODEL,
    error_of,
    read_small,
    write,
)

from rafostrack.config import load_config
from rafostrack.errors import InputError, Warnings
from rafostrack.io.csv_mission import read_arrivals, read_beacons, read_floats

pytestmark = pytest.mark.reliability


def test_missing_file(tmp_path):
    message = error_of(read_beacons, tmp_path / "beacons.csv")
    assert f"{tmp_path / 'beacons.csv'}: file not found (expected a CSV file with columns beacon_id" in message
    assert "config file not found" in error_of(load_config, [tmp_path / "nope.toml"])


def test_empty_file(tmp_path):
    for text in ("", "\n\n  \n"):
        message = error_of(read_beacons, write(tmp_path / "beacons.csv", text))
        assert "beacons.csv: file is empty (expected a header line: beacon_id, lat, lon)" in message


def test_header_only(tmp_path):
    path = write(tmp_path / "beacons.csv", "beacon_id,lat,lon\n")
    assert "beacons.csv: line 2: no rows after the header (header only); expected at least one beacon" in error_of(
        read_beacons, path
    )
    path = write(tmp_path / "floats.csv", "float_id,launch_time,launch_lat,launch_lon\n\n")
    assert "floats.csv: line 2: no rows after the header (header only)" in error_of(read_floats, path, MODEL)
    with pytest.raises(InputError, match=r"f1\.csv: line 2: no rows after the header \(header only\)"):
        read_small(tmp_path, "time,toa_s\n")


def test_missing_required_column_suggests_nearest(tmp_path):
    path = write(tmp_path / "floats.csv", "float_id,launch_time,launch_lt,launch_lon\nf1,2009-01-01,-57,-98\n")
    message = error_of(read_floats, path, MODEL)
    assert (
        "floats.csv: line 1: missing required column 'launch_lat' "
        "(the header has 'launch_lt': did you mean 'launch_lat'?)" in message
    )
    with pytest.raises(InputError, match=r"f1\.csv: line 1: unknown column 'toa' \(did you mean 'toa_s'\?\)"):
        read_small(tmp_path, "time,toa_s,toa\n2009-01-02,1,2\n")


def test_bom_and_crlf_are_accepted(tmp_path):
    plain, _ = read_small(tmp_path)
    for newline, bom in (("\r\n", True), ("\r\n", False), ("\n", True), ("\r", False)):
        table = read_beacons(write(tmp_path / "beacons.csv", BEACONS, newline, bom))
        info = read_floats(write(tmp_path / "floats.csv", FLOATS, newline, bom), MODEL)["f1"]
        warnings = Warnings()
        record = read_arrivals(write(tmp_path / "f1.csv", ARRIVALS, newline, bom), info, table, warnings)
        assert list(table.beacon_id) == ["A", "B"] and info.window_s == 4000
        assert [w.toa_s.tolist() for w in record.windows] == [w.toa_s.tolist() for w in plain.windows]
        assert not warnings.messages


def test_semicolon_separated_file_is_a_clear_error(tmp_path):
    message = error_of(read_beacons, write(tmp_path / "beacons.csv", BEACONS.replace(",", ";")))
    assert "beacons.csv: line 1: columns are separated by ';'; expected ',' (comma-separated CSV" in message
    message = error_of(read_beacons, write(tmp_path / "beacons.csv", BEACONS.replace(",", "\t")))
    assert "columns are separated by tabs" in message


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("beacon_id,lat,lon\nA,1,2\nB,1,2,7\n", "line 3: more fields than the header; expected 3"),
        ("beacon_id,lat,lon\nA,1,2,,9\n", "line 2: 5 fields; expected 3 (as many as the header"),
        ("beacon_id,lat,lon\nA,1,2\nB,1,2,3,4,5\n", "line 3: 6 fields; expected 3"),
        ('beacon_id,lat,lon\nA,1,"2\n', 'cannot parse as CSV: a quote (") is never closed'),
        ('beacon_id,lat,lon\nA,1,"2\n3"\nB,1,2\n', "line 2: a field contains a line break"),
        ("beacon_id,lat,lon,lat\nA,1,2,3\n", "line 1: column 'lat' appears twice"),
        ("beacon_id,lat,lon,\nA,1,2,\n", "line 1: column 4 has no name (a trailing comma?)"),
        ("beacon_id,lat,lon\n\n\nA,1,2\n\nB,x,2\n", "line 6: field 'lat': expected a number, got 'x'"),
        ("\n\nbeacon_id,lat,lon\nA,1,2\nB,1,\n", "line 5: field 'lon' is empty; expected a position in degrees"),
        ("beacon_id,lat,lon\nA,1,2\nB,1,2\xff\n", "line 3: not UTF-8 text (byte 0xff)"),
        ("beacon_id,lat,lon,start,end\nA,1,2,2009-02-01,2009-01-01\n", "line 2: field 'end': 2009-01-01T00:00:00Z"),
    ],
)
def test_csv_structure_errors_name_the_line(tmp_path, text, needle):
    path = tmp_path / "beacons.csv"
    path.write_bytes(text.encode("latin-1"))
    message = error_of(read_beacons, path)
    assert f"{path}: {needle}" in message
