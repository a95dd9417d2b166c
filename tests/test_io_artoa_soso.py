"""ARTOA sound-source file reader (`rafostrack.io.artoa_soso`): strict, with explicit errors."""

from __future__ import annotations

import dataclasses
import shutil

import numpy as np
import pandas as pd
import pytest
from field_files import OPTIONS, csv_run, write_soso

import rafostrack
from rafostrack.errors import InputError
from rafostrack.io import read_beacons, reader_for


def test_round_trip_equals_the_csv_run(quality_mission, tmp_path):
    mission = tmp_path / "m"
    shutil.copytree(quality_mission, mission)
    write_soso(mission / "beacons.csv", mission / "soso.dat")
    csv_table = read_beacons(mission / "beacons.csv")
    (mission / "beacons.csv").unlink()
    assert reader_for("beacons", mission / "soso.dat").format == "artoa-soso"
    table = read_beacons(mission / "soso.dat")
    for f in dataclasses.fields(table):
        a, b = getattr(table, f.name), getattr(csv_table, f.name)
        if a is not None:
            np.testing.assert_array_equal(a, b)
    run = rafostrack.track(mission / "sim1.csv", **OPTIONS)  # finds soso.dat beside the float file
    base = csv_run(quality_mission)
    pd.testing.assert_frame_equal(run.track, base.track)


@pytest.mark.parametrize(
    ("line", "needle"),
    [
        ("A -58 -100 2009-01-01 - 0", "line 2: 6 fields; expected 7: name lat lon begin end offset_s drift_s_per_day"),
        ("A -58 -100 14536 - 0 0", "field 'begin': expected an ISO-8601 date or time or '-', got '14536' (a RAFOS day"),
        ("A 58S -100 - - 0 0", "field 'lat': expected a number, got '58S'"),
        ("A -95 -100 - - 0 0", "field 'lat': expected a finite number in [-90, 90], got '-95'"),
    ],
)
def test_anything_undocumented_is_an_explicit_error(tmp_path, line, needle):
    path = tmp_path / "x.soso"
    path.write_text(f"% sources\n{line}\n")
    with pytest.raises(InputError) as err:
        read_beacons(path)
    assert needle in str(err.value) and len(str(err.value).splitlines()) == 1
