"""The CSV mission reader (`rafostrack.io.csv_mission`): beacons.csv, floats.csv, arrival files.

One test per row of the "Input checks" table of docs/user-guide.md, then property-based tests (random and
mutated CSV: only `InputError` may escape, with a one-line message) and a 1,000,000-row float
file in bounded memory. `pytest -m reliability` runs the hardening tests alone.
"""

from __future__ import annotations

import datetime as dt
import json
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from support import (
    ARRIVALS,
    BEACONS,
    FLOATS,
    MODEL,
    daily_rows,
    error_of,
    fuzz_settings,
    needs_hypothesis,
    only_input_error,
    read_small,
    write,
)

from rafostrack.cli import main
from rafostrack.errors import InputError, Warnings
from rafostrack.io.csv_mission import read_arrivals, read_beacons, read_floats
from rafostrack.io.records import USABLE_GAP_DAYS

try:
    from hypothesis import given
    from hypothesis import strategies as st
except ImportError:  # pragma: no cover - hypothesis is a test dependency
    st = None


pytestmark = pytest.mark.reliability


@pytest.mark.parametrize(
    ("name", "text", "needle"),
    [
        ("beacons.csv", "beacon_id,lat,lon\nA,abc,2\n", "line 2: field 'lat': expected a number, got 'abc'"),
        ("beacons.csv", "beacon_id,lat,lon,offset_s\nA,1,2,ten\n", "line 2: field 'offset_s': expected a number"),
        (
            "floats.csv",
            "float_id,launch_time,launch_lat,launch_lon,max_signals\nf1,2009-01-01,1,2,2.5\n",
            "line 2: field 'max_signals': expected a whole number >= 1, got '2.5'",
        ),
        (
            "floats.csv",
            "float_id,launch_time,launch_lat,launch_lon,window_s\nf1,2009-01-01,1,2,-5\n",
            "line 2: field 'window_s': expected a finite value > 0, got '-5'",
        ),
        ("f1.csv", "time,toa_s\n2009-01-02,1\n2009-01-02,x\n", "line 3: field 'toa_s': expected a number, got 'x'"),
    ],
)
def test_wrong_types(tmp_path, name, text, needle):
    if name == "f1.csv":
        with pytest.raises(InputError) as err:
            read_small(tmp_path, text)
        message = str(err.value)
    elif name == "floats.csv":
        message = error_of(read_floats, write(tmp_path / name, text), MODEL)
    else:
        message = error_of(read_beacons, write(tmp_path / name, text))
    assert f"{name}: {needle}" in message


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("beacon_id,lat,lon\nA,nan,2\n", "line 2: field 'lat': expected a finite number in [-90, 90], got 'nan'"),
        ("beacon_id,lat,lon\nA,1,inf\n", "line 2: field 'lon': expected a finite number in [-180, 360], got 'inf'"),
        ("beacon_id,lat,lon\nA,1,2\nB,-Infinity,2\n", "line 3: field 'lat': expected a finite number"),
        (
            "beacon_id,lat,lon,offset_s\nA,1,2,1e400\n",
            "line 2: field 'offset_s': expected a finite number, got '1e400'",
        ),
    ],
)
def test_nan_and_inf_coordinates(tmp_path, text, needle):
    assert f"beacons.csv: {needle}" in error_of(read_beacons, write(tmp_path / "beacons.csv", text))


def test_lat_lon_out_of_range(tmp_path):
    message = error_of(read_beacons, write(tmp_path / "beacons.csv", "beacon_id,lat,lon\nA,95,2\n"))
    assert "beacons.csv: line 2: field 'lat': expected a finite value in [-90, 90], got '95'" in message
    text = "float_id,launch_time,launch_lat,launch_lon\nf1,2009-01-01,-57,400\n"
    message = error_of(read_floats, write(tmp_path / "floats.csv", text), MODEL)
    assert "floats.csv: line 2: field 'launch_lon': expected a finite value in [-180, 360], got '400'" in message


def test_duplicate_beacon_ids(tmp_path):
    text = "beacon_id,lat,lon\nA,1,2\nB,1,3\nA,3,4\n"
    message = error_of(read_beacons, write(tmp_path / "beacons.csv", text))
    assert "beacons.csv: line 4: duplicate beacon_id 'A' (first on line 2); field 'beacon_id'" in message


@pytest.mark.parametrize("bad", ["yesterday", "2009-02-30", "3000-01-01", "2009-01-02T25:00Z", "01/02/2009 x"])
def test_unparsable_times(tmp_path, bad):
    with pytest.raises(InputError) as err:
        read_small(tmp_path, f"time,toa_s\n2009-01-02T00:00Z,1\n{bad},2\n")
    assert "f1.csv: line 3: field 'time': expected an ISO-8601 time (e.g. 2009-01-23T00:00:00Z" in str(err.value)
    assert repr(bad) in str(err.value)


def test_timezone_less_times_are_utc(tmp_path):
    """Documented choice: a time without a zone is UTC; explicit offsets are converted."""
    texts = ["2009-01-02T06:00:00", "2009-01-02T06:00:00Z", "2009-01-02T08:00:00+02:00", "2009-01-02 06:00"]
    times = []
    for text in texts:
        record, warnings = read_small(tmp_path, f"time,toa_s\n{text},100\n")
        times.append(record.windows[0].time)
        assert not warnings.messages
    assert times == [np.datetime64("2009-01-02T06:00:00", "ns")] * len(texts)
    floats = "float_id,launch_time,launch_lat,launch_lon\nf1,2009-01-01T00:00,-57,-98\n"
    assert read_floats(write(tmp_path / "floats.csv", floats), MODEL)["f1"].launch_time == np.datetime64(
        "2009-01-01T00:00", "ns"
    )


def test_negative_toa_is_dropped_with_warning(tmp_path):
    record, warnings = read_small(tmp_path, "time,toa_s\n2009-01-02,100\n2009-01-02,-3.5\n")
    assert record.windows[0].toa_s.tolist() == [100.0]
    assert any(
        "1 TOA(s) outside the window [0, 4000] s dropped (1 negative, 0 beyond window_s; first at line 3: "
        "field 'toa_s' = -3.5)" in m
        for m in warnings.messages
    )


def test_toa_beyond_window_is_dropped_with_warning(tmp_path):
    record, warnings = read_small(tmp_path, "time,toa_s\n2009-01-02,4000.5\n2009-01-02,100\n2009-01-03,4001\n")
    assert [w.toa_s.tolist() for w in record.windows] == [[100.0], []]  # the emptied window is kept
    assert any("2 TOA(s) outside the window [0, 4000] s dropped (0 negative, 2 beyond" in m for m in warnings.messages)


def test_more_toas_than_max_signals_keeps_earliest(tmp_path):
    text = "time,toa_s\n" + "".join(f"2009-01-02,{t}\n" for t in (400, 100, 300, 200, 500))
    record, warnings = read_small(tmp_path, text)
    assert record.windows[0].toa_s.tolist() == [100.0, 200.0, 300.0]  # max_signals = 3
    assert any(
        "1 window(s) held more than max_signals=3 TOAs; kept the earliest (first: window 2009-01-02T00:00:00Z, "
        "line 2 left out)" in m
        for m in warnings.messages
    )


def test_float_id_missing_from_floats_csv(tmp_path):
    mission = tmp_path / "m"
    mission.mkdir()
    write(mission / "beacons.csv", BEACONS)
    write(mission / "floats.csv", FLOATS)
    write(mission / "f2.csv", ARRIVALS)
    result = CliRunner().invoke(main, ["track", str(mission / "f2.csv"), "--out", str(tmp_path / "out")])
    assert result.exit_code == 2
    assert result.stderr.strip() == (
        f"rafostrack: error: {mission / 'floats.csv'}: no row for float_id 'f2' (the arrival file's name); known: f1"
    )


@pytest.mark.parametrize(
    ("ids", "named", "hint"),
    [
        # another float's number is no typo: float767 was suggested for float811
        (["float767"], "float811", "; known: float767"),
        (["float767", "float812"], "float811", "; known: float767, float812"),
        (["Float811", "f811"], "float811", " (did you mean 'Float811'?); known: Float811, f811"),  # both are 811
        (
            [f"float{700 + i}" for i in range(14)],
            "float811",
            "; known: float700, float701, " + ", ".join(f"float{700 + i}" for i in range(2, 10)) + " and 4 more",
        ),
    ],
)
def test_float_id_missing_from_floats_csv_suggests_only_a_close_id(tmp_path, ids, named, hint):
    mission = tmp_path / "m"
    mission.mkdir()
    write(mission / "beacons.csv", BEACONS)
    rows = "".join(f"{f},2009-01-01T00:00:00Z,-57,-98,4000,3\n" for f in ids)
    write(mission / "floats.csv", FLOATS.splitlines()[0] + "\n" + rows)
    write(mission / f"{named}.csv", ARRIVALS)
    result = CliRunner().invoke(main, ["track", str(mission / f"{named}.csv"), "--out", str(tmp_path / "out")])
    assert result.exit_code == 2
    assert result.stderr.strip() == (
        f"rafostrack: error: {mission / 'floats.csv'}: no row for float_id {named!r} (the arrival file's name){hint}"
    )


def test_launch_after_first_window(tmp_path):
    with pytest.raises(InputError) as err:
        read_small(tmp_path, "time,toa_s\n2009-01-02,1\n2008-12-31T00:00Z,100\n")
    assert (
        "f1.csv: line 3: window at 2008-12-31T00:00:00Z is before the float's launch_time 2009-01-01T00:00:00Z; "
        "field 'time': expected windows at or after the launch" in str(err.value)
    )


def test_no_beacon_active_at_some_window(tmp_path):
    beacons = "beacon_id,lat,lon,start,end\nA,-58,-100,,2009-01-03T12:00Z\nB,-56,-95,2009-01-05,\n"
    record, warnings = read_small(tmp_path, daily_rows("2009-01-02", 6), beacons=beacons)
    assert len(record.windows) == 6
    assert warnings.messages == [
        f"{tmp_path / 'f1.csv'}: 1 window(s) with no active beacon (beacons.csv start/end), tracked by the drift "
        "model only: 2009-01-04T00:00:00Z"
    ]


def test_no_usable_beacon_for_many_days(tmp_path):
    # Beacon A stops on Jan 10, B starts on Jan 25: no active beacon for two weeks.
    beacons = "beacon_id,lat,lon,start,end\nA,-58,-100,,2009-01-10\nB,-56,-95,2009-01-25,\n"
    _, warnings = read_small(tmp_path, daily_rows("2009-01-02", 30), beacons=beacons)
    text = " | ".join(warnings.messages)
    assert "14 window(s) with no active beacon" in text
    assert "2009-01-11T00:00:00Z to 2009-01-24T00:00:00Z (14 windows)" in text
    assert (
        f"no usable beacon (no window with an active beacon and a stored TOA) for more than {USABLE_GAP_DAYS:g} "
        "days: 2009-01-10T00:00:00Z to 2009-01-25T00:00:00Z (15.0 days)" in text
    )
    # Beacons active, but nothing stored for 12 days (and a hole in the file): the same warning.
    arrivals = daily_rows("2009-01-02", 3) + daily_rows("2009-01-05", 12, toas="").split("\n", 1)[1]
    arrivals += daily_rows("2009-02-01", 2).split("\n", 1)[1]
    _, warnings = read_small(tmp_path, arrivals)
    assert warnings.messages == [
        f"{tmp_path / 'f1.csv'}: no usable beacon (no window with an active beacon and a stored TOA) for more "
        "than 10 days: 2009-01-04T00:00:00Z to 2009-02-01T00:00:00Z (28.0 days); the track there follows the "
        "drift model only"
    ]


_MEMORY_SCRIPT = textwrap.dedent(
    """
    import json, resource, sys, time
    from pathlib import Path
    import numpy as np
    from rafostrack.errors import Warnings
    from rafostrack.domain import FloatInfo
    from rafostrack.io.csv_mission import read_arrivals, read_beacons

    def peak_kb():
        # VmHWM is this process's own peak RSS (ru_maxrss can carry the parent's across exec).
        try:
            with open("/proc/self/status") as fh:
                return next(int(line.split()[1]) for line in fh if line.startswith("VmHWM:"))
        except (OSError, StopIteration):
            return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * (1 if sys.platform != "darwin" else 1 / 1024)

    before = peak_kb()
    beacons = read_beacons(Path(sys.argv[1]) / "beacons.csv")
    nat = np.datetime64("NaT", "ns")
    info = FloatInfo("f1", np.datetime64("1989-12-31", "ns"), -57.0, -98.0, nat, np.nan, np.nan, 0.0, 0.0, 4200.0, 4)
    warnings = Warnings()
    start = time.perf_counter()
    record = read_arrivals(Path(sys.argv[1]) / "f1.csv", info, beacons, warnings)
    seconds = time.perf_counter() - start
    peak = peak_kb()
    print(json.dumps({"before_mb": before / 1024, "peak_mb": peak / 1024, "seconds": seconds,
                      "windows": len(record.windows), "toas": sum(w.n_signals for w in record.windows),
                      "warnings": warnings.messages}))
    """
)


@pytest.mark.slow
def test_million_row_float_file_in_bounded_memory(tmp_path):
    """1,000,000 rows (250,000 two-hourly windows of 4 TOAs, 28 MB) read and validated in a
    fresh process: peak RSS 0.40 GB (0.10 GB of it before reading), about 2 s."""
    n_windows = 250_000
    times = np.datetime_as_string(np.datetime64("1990-01-01T00:00:00", "s") + np.arange(n_windows) * 7200)
    toa = np.arange(n_windows * 4).reshape(-1, 4) % 997 * 4.0 + 1.5  # distinct within each window
    with open(tmp_path / "f1.csv", "w") as fh:
        fh.write("time,toa_s\n")
        for a in range(0, n_windows, 50_000):
            rows = zip(times[a : a + 50_000], toa[a : a + 50_000], strict=True)
            fh.write("".join(f"{t}Z,{x:g}\n" for t, row in rows for x in row))
    write(tmp_path / "beacons.csv", "beacon_id,lat,lon\nA,-58,-100\nB,-56,-95\n")
    proc = subprocess.run(
        [sys.executable, "-c", _MEMORY_SCRIPT, str(tmp_path)], capture_output=True, text=True, check=False, timeout=120
    )
    assert proc.returncode == 0, proc.stderr
    stats = json.loads(proc.stdout)
    print(
        f"1e6 rows: peak RSS {stats['peak_mb']:.0f} MB (before reading {stats['before_mb']:.0f} MB), "
        f"{stats['seconds']:.1f} s"
    )
    assert stats["windows"] == n_windows and stats["toas"] == 4 * n_windows
    assert stats["warnings"] == []
    assert stats["peak_mb"] < 1024, stats


def test_half_given_end_fix_is_an_error(tmp_path):
    text = (
        "float_id,launch_time,launch_lat,launch_lon,end_time,end_lat,end_lon\nf1,2009-01-01,-57,-98,2009-06-01,-58,\n"
    )
    message = error_of(read_floats, write(tmp_path / "floats.csv", text), MODEL)
    assert "floats.csv: line 2: field 'end_lon' is empty; expected both end_lat and end_lon, or neither" in message


def test_duplicate_rows_and_mixed_empty_rows_are_warned(tmp_path):
    text = "time,toa_s\n2009-01-02,100\n2009-01-02,100\n2009-01-02,\n2009-01-02T00:30Z,5\n"
    record, warnings = read_small(tmp_path, text)
    assert [w.toa_s.tolist() for w in record.windows] == [[100.0], [5.0]]
    text = " | ".join(warnings.messages)
    assert "1 duplicate row(s) (same time and toa_s) dropped (first at line 3)" in text
    assert "1 window(s) have both an empty toa_s row and TOAs" in text
    assert "1 window(s) open less than window_s=4000 s after the previous one" in text


_SEEDS = {
    "beacons.csv": b"beacon_id,lat,lon,offset_s,start,end,drift_s_per_day\nA,-58,-100,0,,,0\n"
    b"B,-56,-95,600,2009-01-01,2010-01-01T00:00Z,0.5\n",
    "floats.csv": (
        b"float_id,launch_time,launch_lat,launch_lon,end_time,end_lat,end_lon,clock_offset_start_s,"
        b"clock_offset_end_s,window_s,max_signals\nf1,2009-01-01T00:00:00Z,-57,-98,2010-01-01,-58,-97,1,-2,4000,3\n"
    ),
    "f1.csv": b"time,toa_s,quality,beacon_id\n2009-01-02T00:00:00Z,632.9,3,A\n2009-01-02T00:00:00Z,1106,,\n"
    b"2009-01-03T00:00Z,,,\n",
}


_COLUMNS = {
    "beacons.csv": (["beacon_id", "lat", "lon"], ["offset_s", "start", "end", "drift_s_per_day"]),
    "floats.csv": (
        ["float_id", "launch_time", "launch_lat", "launch_lon"],
        ["end_time", "end_lat", "end_lon", "clock_offset_start_s", "clock_offset_end_s", "window_s", "max_signals"],
    ),
    "f1.csv": (["time", "toa_s"], ["quality", "beacon_id"]),
}


_TOKENS = [
    *(bytes([c]) for c in b',;"\n\r \t0123456789.-+eEZT:naif\x00\xef\xbb\xbf\xff'),
    b"nan",
    b"inf",
    b"2009-01-24",
    b"T00:00Z",
    b"1e400",
    b",,",
    b"\r\n",
]


def _cell_values():
    """Per-column cells: mostly plausible values, sometimes odd ones."""
    times = st.datetimes(dt.datetime(2008, 12, 1), dt.datetime(2011, 1, 1)).map(lambda d: d.isoformat())
    window_times = st.integers(0, 40).map(lambda k: (dt.datetime(2009, 1, 1) + dt.timedelta(days=k)).isoformat() + "Z")

    def number(lo, hi):
        plain = st.one_of(st.floats(lo, hi).map(lambda v: f"{v:.6g}"), st.integers(int(lo), int(hi)).map(str))
        edge = st.sampled_from(["inf", "-inf", "nan", "1e400", "-0", "1e-400", f"{hi:g}", f"{lo:g}"])
        return st.one_of(*[plain] * 9, edge)

    opt_time = st.one_of(st.just(""), times)
    values = {
        "beacon_id": st.sampled_from(["A", "B", "", "", "A", "B", "", "", "C"]),
        "lat": number(-95, 95),
        "lon": number(-200, 400),
        "offset_s": number(-1e4, 1e4),
        "drift_s_per_day": number(-10, 10),
        "start": opt_time,
        "end": opt_time,
        "float_id": st.sampled_from(["f1", "f2", ""]),
        "launch_time": times,
        "end_time": opt_time,
        "launch_lat": number(-95, 95),
        "launch_lon": number(-200, 400),
        "end_lat": st.one_of(st.just(""), number(-95, 95)),
        "end_lon": st.one_of(st.just(""), number(-200, 400)),
        "clock_offset_start_s": number(-100, 100),
        "clock_offset_end_s": st.one_of(st.just(""), number(-100, 100)),
        "window_s": st.one_of(st.just(""), number(-1, 1e5)),
        "max_signals": st.one_of(st.just(""), number(0, 20), st.just("1e9")),
        "time": window_times,
        "toa_s": st.one_of(st.just(""), number(-100, 5000)),
        "quality": number(0, 100),
    }
    odd = st.one_of(
        st.sampled_from(["", "nan", "inf", "-inf", "1e400", "x", " ", '""', "2009-02-30", "3000-01-01", '"a,b"']),
        st.text(max_size=5),
    )
    return values, odd


def _csv_documents(name: str):
    """Whole CSV files: plausible tables (valid header, odd cells, ragged rows, line endings,
    BOM), random bytes, and byte-level mutations of a valid file."""
    values, odd = _cell_values()
    edge_cells = st.sampled_from(["inf", "-inf", "nan", "1e400", "-1e400", "1e9", "-1", "0", "1.5", "", " "])
    required, optional = _COLUMNS[name]
    ids = {"beacon_id", "float_id"} if name != "f1.csv" else set()

    @st.composite
    def table(draw):
        cols = draw(st.permutations(required + draw(st.lists(st.sampled_from(optional), unique=True))))
        if draw(st.integers(0, 9)) == 0:  # a damaged header
            cols = draw(st.lists(st.sampled_from([*cols, "lng", "Time", ""]), min_size=1, max_size=len(cols) + 1))
        rows = []
        for i in range(draw(st.integers(0, 12))):
            # Ids are mostly unique so that the later columns get checked too.
            unique = draw(st.integers(0, 9)) > 0
            rows.append([f"x{i}" if c in ids and unique else draw(values.get(c, odd)) for c in cols])
        for _ in range(draw(st.integers(0, 2)) if rows else 0):  # a few damaged cells or ragged rows
            row = rows[draw(st.integers(0, len(rows) - 1))]
            if draw(st.booleans()) and row:
                row[draw(st.integers(0, len(row) - 1))] = draw(odd)
            else:
                row[draw(st.integers(0, len(row))) :] = draw(st.lists(odd, max_size=3))
        newline = draw(st.sampled_from(["\n", "\r\n", "\r"]))
        text = newline.join([",".join(cols)] + [",".join(r) for r in rows]) + draw(st.sampled_from(["", newline]))
        bom = b"\xef\xbb\xbf" if draw(st.booleans()) else b""
        return bom + text.encode("utf-8", "replace")

    @st.composite
    def mutated(draw):
        data = bytearray(_SEEDS[name])
        for _ in range(draw(st.integers(1, 6))):
            i = draw(st.integers(0, len(data)))
            op = draw(st.integers(0, 3))
            if op == 0:
                data[i:i] = draw(st.sampled_from(_TOKENS))
            elif op == 1:
                del data[i : i + draw(st.integers(1, 20))]
            elif op == 2 and i < len(data):
                data[i] = draw(st.integers(0, 255))
            else:
                j = min(len(data), i + draw(st.integers(1, 40)))
                data[j:j] = data[i:j]
        return bytes(data)

    @st.composite
    def one_cell(draw):
        """A valid file with one cell replaced: every column meets every kind of bad value."""
        lines = _SEEDS[name].decode().splitlines()
        header = lines[0].split(",")
        row = draw(st.integers(1, len(lines) - 1))
        cells = lines[row].split(",")
        col = draw(st.integers(0, len(header) - 1))
        cells[col] = draw(st.one_of(values.get(header[col], odd), odd, edge_cells))
        lines[row] = ",".join(cells)
        return ("\n".join(lines) + "\n").encode("utf-8", "replace")

    return st.one_of(one_cell(), one_cell(), table(), table(), mutated(), st.binary(max_size=120))


_BAD_CELLS = ["inf", "-inf", "nan", "NaN", "1e400", "-1e400", "1e9", "-1", "0", "0.5", "", " ", "x", '"a,b"', "1,2"]


_BAD_CELLS += ["2009-02-30", "3000-01-01", "1600-01-01", "2009-01-01T00:00:00+25:00", "\u00e9", "0x10", "1_0"]


def _finite_fields(obj) -> bool:
    values = [v for v in vars(obj).values() if isinstance(v, float | np.ndarray) and np.asarray(v).dtype.kind == "f"]
    return all(np.isfinite(np.asarray(v)[~np.isnan(np.asarray(v))]).all() for v in values)


@pytest.mark.slow
def test_every_column_against_every_bad_cell(tmp_path):
    """Exhaustive grid: each column of a valid file replaced by each odd value. Only
    InputError (one line, naming the file, line and column) escapes; what is accepted is finite."""
    beacons = read_beacons(write(tmp_path / "beacons.csv", BEACONS))
    info = read_floats(write(tmp_path / "floats.csv", FLOATS), MODEL)["f1"]
    readers = {
        "beacons.csv": lambda p: [read_beacons(p)],
        "floats.csv": lambda p: list(read_floats(p, MODEL).values()),
        "f1.csv": lambda p: list(read_arrivals(p, info, beacons, Warnings()).windows),
    }
    for name, read in readers.items():
        header, *rows = _SEEDS[name].decode().splitlines()
        for col, column in enumerate(header.split(",")):
            for bad in _BAD_CELLS:
                cells = rows[0].split(",")
                cells[col] = bad
                path = tmp_path / "case" / name
                path.parent.mkdir(exist_ok=True)
                path.write_text("\n".join([header, ",".join(cells), *rows[1:]]) + "\n")
                try:
                    accepted = read(path)
                except InputError as exc:
                    message = str(exc)
                    assert len(message.splitlines()) == 1 and message.startswith(f"{path}: "), message
                    if bad not in ("1,2", '"a,b"') and "fields" not in message:
                        assert "line 2" in message and f"'{column}'" in message, message
                else:
                    assert bad != "1,2", f"{name}: a row with an extra field was accepted"
                    assert all(_finite_fields(item) for item in accepted), (name, column, bad)


def _fuzz_reader(tmp_path: Path, name: str, read) -> None:
    path = tmp_path / name

    @fuzz_settings()
    @given(_csv_documents(name))
    def run(data: bytes) -> None:
        path.write_bytes(data)
        only_input_error(read, path)

    run()


@needs_hypothesis
@pytest.mark.filterwarnings("error")
def test_fuzz_beacons_csv(tmp_path):
    _fuzz_reader(tmp_path, "beacons.csv", read_beacons)


@needs_hypothesis
@pytest.mark.filterwarnings("error")
def test_fuzz_floats_csv(tmp_path):
    _fuzz_reader(tmp_path, "floats.csv", lambda p: read_floats(p, MODEL))


@needs_hypothesis
@pytest.mark.filterwarnings("error")
def test_fuzz_float_file(tmp_path):
    beacons = read_beacons(write(tmp_path / "beacons.csv", BEACONS))
    info = read_floats(write(tmp_path / "floats.csv", FLOATS), MODEL)["f1"]
    _fuzz_reader(tmp_path, "f1.csv", lambda p: read_arrivals(p, info, beacons, Warnings()))


# --------------------------------------------------------------------------------------
# Reading well-formed and mildly odd missions


def test_reads_windows_sorted_in_any_row_order(tmp_path):
    record, warnings = read_small(
        tmp_path,
        "time,toa_s\n2009-01-03T00:00Z,300\n2009-01-02T00:00Z,200\n2009-01-02T00:00Z,100\n2009-01-04T00:00Z,\n",
    )
    assert [w.toa_s.tolist() for w in record.windows] == [[100.0, 200.0], [300.0], []]
    assert record.windows[0].time == np.datetime64("2009-01-02T00:00", "ns")
    assert len(warnings) == 0


def test_beacon_active_period(tmp_path):
    text = "beacon_id,lat,lon,offset_s,start,end\nA,-58,-100,0,,\nB,-56,-95,600,2009-06-01,\n"
    beacons = read_beacons(write(tmp_path / "beacons.csv", text))
    assert beacons.active_at(np.datetime64("2009-01-01", "ns")).tolist() == [True, False]
    assert beacons.active_at(np.datetime64("2009-07-01", "ns")).tolist() == [True, True]


def test_recoverable_oddities_are_warned_not_silent(tmp_path):
    record, warnings = read_small(
        tmp_path,
        "time,toa_s\n"
        "2009-01-02T00:00Z,100\n2009-01-02T00:00Z,100\n"  # duplicate
        "2009-01-02T00:00Z,4500\n"  # beyond the 4000 s window
        "2009-01-03T00:00Z,1\n2009-01-03T00:00Z,2\n2009-01-03T00:00Z,3\n2009-01-03T00:00Z,4\n",  # > max 3
    )
    assert [w.toa_s.tolist() for w in record.windows] == [[100.0], [1.0, 2.0, 3.0]]
    text = " | ".join(warnings.messages)
    assert "duplicate" in text and "outside the window" in text and "max_signals=3" in text


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("beacon_id,lat,lng\nA,1,2\n", "missing required column 'lon' (the header has 'lng': did you mean 'lon'?)"),
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
        read_beacons(write(tmp_path / "beacons.csv", text))
    assert needle in str(err.value) and "beacons.csv" in str(err.value)


def test_window_before_launch_is_an_error(tmp_path):
    with pytest.raises(InputError, match="line 2: window at 2008-12-31T00:00:00Z is before the float's launch_time"):
        read_small(tmp_path, "time,toa_s\n2008-12-31T00:00Z,100\n")


def test_unknown_label(tmp_path):
    with pytest.raises(InputError, match="unknown beacon 'C'"):
        read_small(tmp_path, "time,toa_s,beacon_id\n2009-01-02T00:00Z,100,C\n")


def test_labels_are_kept_with_their_toas(tmp_path):
    record, _ = read_small(tmp_path, "time,toa_s,beacon_id\n2009-01-02T00:00Z,300,A\n2009-01-02T00:00Z,100,\n")
    assert record.windows[0].beacon_id == (None, "A")
    assert record.has_labels


def test_empty_optional_cells_take_defaults(tmp_path):
    beacons = read_beacons(
        write(tmp_path / "beacons.csv", "beacon_id,lat,lon,offset_s,drift_s_per_day\nA,-58,-100,,\n")
    )
    assert beacons.offset_s.tolist() == [0.0] and beacons.drift_s_per_day.tolist() == [0.0]
    floats = "float_id,launch_time,launch_lat,launch_lon,window_s,max_signals\nf1,2009-01-01,-57,-98,,\n"
    info = read_floats(write(tmp_path / "floats.csv", floats), MODEL)["f1"]
    assert info.window_s == MODEL.window_s and info.max_signals == MODEL.max_signals
