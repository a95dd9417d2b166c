"""io/records.py's refusal of records that cannot give a track (`check_usable`): no usable
TOA at all, or TOAs in too few windows, is a one-line input error naming the likely cause,
never a track from the drift model alone; and the TOAs it leaves out past the window, kept
aside for a longer one."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from support import FLOATS, daily_rows, error_of, read_small

from rafostrack.io.records import MIN_HEARD_SHARE, MIN_WINDOWS_FOR_SHARE, with_longer_window


def _in_milliseconds(rows: str) -> str:
    head, *lines = rows.strip().split("\n")
    return "\n".join([head, *(f"{t},{float(toa) * 1000:g}" for t, toa in (line.split(",") for line in lines))]) + "\n"


def test_toas_in_milliseconds_are_refused_with_the_unit_named(tmp_path: Path) -> None:
    message = error_of(read_small, tmp_path, _in_milliseconds(daily_rows("2009-01-02", 30)))
    assert "f1.csv: no track from this record: all 60 TOAs lie outside the window [0, 4000] s" in message
    assert "unit of toa_s (milliseconds?)" in message and "window_s in floats.csv" in message


def test_a_file_with_every_toa_empty_is_refused(tmp_path: Path) -> None:
    rows = "time,toa_s\n" + "".join(f"2009-01-{d:02d}T00:00:00Z,\n" for d in range(2, 28))
    message = error_of(read_small, tmp_path, rows)
    assert message.endswith(
        "every toa_s is empty; expected arrival times in seconds (is this the float's arrival file?)"
    )


def test_toas_in_too_few_windows_are_refused(tmp_path: Path) -> None:
    """30 windows, 2 with a TOA inside the window (7% < 10%): refused; 3 (10%): accepted."""
    heard = daily_rows("2009-01-02", 30, toas="100").split("\n")
    for kept, refused in ((2, True), (3, False)):
        rows = [heard[0]] + [line if k < kept else line.replace(",100", ",9000") for k, line in enumerate(heard[1:-1])]
        text = "\n".join(rows) + "\n"
        if refused:
            message = error_of(read_small, tmp_path, text)
            assert f"only {kept} of 30 windows (7%) hold a TOA inside the window" in message
            assert f"at least {MIN_HEARD_SHARE:.0%} expected" in message
        else:
            record, _ = read_small(tmp_path, text)
            assert sum(w.n_signals > 0 for w in record.windows) == kept


@pytest.mark.parametrize("n_windows", [1, MIN_WINDOWS_FOR_SHARE - 1])
def test_a_short_record_with_one_heard_window_is_kept(tmp_path: Path, n_windows: int) -> None:
    """Below `MIN_WINDOWS_FOR_SHARE` windows the share is not judged: one heard window is enough."""
    rows = daily_rows("2009-01-02", n_windows, toas="100").split("\n")
    text = "\n".join([rows[0], rows[1], *(line.replace(",100", ",") for line in rows[2:-1])]) + "\n"
    record, _ = read_small(tmp_path, text)
    assert len(record.windows) == n_windows


def test_toas_past_the_window_are_kept_aside_and_taken_back_with_their_labels(tmp_path: Path) -> None:
    """TOAs later than window_s (4000 s) stay out of their windows but on the record
    (`ArrivalRecord.late`, with their labels); a longer window takes back those it covers,
    while their window holds fewer than max_signals (3) TOAs, as reading with it would."""
    rows = (
        "time,toa_s,beacon_id\n"
        "2009-01-02T00:00:00Z,100,A\n2009-01-02T00:00:00Z,4600,\n2009-01-02T00:00:00Z,4500,B\n"
        "2009-01-03T00:00:00Z,100,A\n2009-01-03T00:00:00Z,200,B\n2009-01-03T00:00:00Z,300,\n"
        "2009-01-03T00:00:00Z,4100,A\n"
    )
    record, _ = read_small(tmp_path, rows)
    assert [(a.window, a.toa_s, a.beacon_id) for a in record.late] == [
        (0, 4500.0, "B"),
        (0, 4600.0, None),
        (1, 4100.0, "A"),
    ]
    assert list(record.windows[0].toa_s) == [100.0]
    longer = with_longer_window(record, 4550.0, 3)
    assert list(longer.windows[0].toa_s) == [100.0, 4500.0] and longer.windows[0].beacon_id == ("A", "B")
    assert list(longer.windows[1].toa_s) == [100.0, 200.0, 300.0]  # full: 4100 stays out
    assert [a.toa_s for a in longer.late] == [4600.0]
    reread, _ = read_small(tmp_path, rows, floats=FLOATS.replace(",4000,", ",4550,"))
    for a, b in zip(longer.windows, reread.windows, strict=True):
        assert np.array_equal(a.toa_s, b.toa_s) and a.beacon_id == b.beacon_id
