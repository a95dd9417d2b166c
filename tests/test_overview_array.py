"""The mission overview's array section (`batch/overview_array.py`): what each mission's
array fit left in OUT/<mission> (array.csv, array.json, beacons-calibrated.csv, array.png)
shown on overview.html, and nothing but a line when those files cannot be read.

Each test writes a tiny output tree by hand: a batch-summary.csv with one failed float of
mission `m` (so `summarise_tree` finds the mission without tracking anything) and the
array's files, their rows inline.
"""

from __future__ import annotations

import html
import json
import re
from pathlib import Path

import pytest
from click.testing import CliRunner

from rafostrack.batch.overview import OVERVIEW_HTML, summarise_tree, write_overview
from rafostrack.cli import main
from rafostrack.mission.outputs import ARRAY_COLUMNS

HEADER = "source,field,given,estimated,shift,sd,unit,at,outcome,calibrated,floats,arrivals,line"
CONTRADICTED = "B1,offset_s,300.0,902.396,,1.536,s,,contradicted,902.396,9,716.4,2"
UNDETERMINED = "B2,position,-58.1010 -97.9600,-58.1305 -98.0192,4.79,3.5,lat lon,,undetermined,,3,80.2,3"
# A source's clock over the mission: contradicted, but no table cell (its offset is).
CLOCK = "B1,clock_s,300.0,902.396,,0.815,s,2009-06-01T12:00,contradicted,,9,716.4,2"
CONSISTENT = [
    "B1,drift_s_per_day,0.0,-0.00143,,0.00315,s/day,,consistent,,9,716.4,2",
    "B2,offset_s,900.0,899.58,,0.352,s,,consistent,,3,80.2,3",
]
CALIBRATED = "beacon_id,lat,lon,offset_s,drift_s_per_day\nB1,-55.996,-109.9102,902.396,0\nB2,-58.101,-97.96,900,0\n"
ROUNDS = [
    {"round": 1, "floats": 11, "decided": ["B1 offset_s"], "rms_residual_s": 2.345, "settled": False},
    {"round": 2, "floats": 12, "decided": ["B1 offset_s"], "rms_residual_s": 1.234, "settled": True},
]
TITLE = "The array, as the mission fitted it: m"


def _tree(out: Path, rows: list[str] | None, rounds: list | None = ROUNDS, calibrated: str | None = None) -> Path:
    """OUT with one failed float of mission m and, per argument given, the array's files."""
    (out / "m").mkdir(parents=True)
    (out / "batch-summary.csv").write_text(
        "mission,float_id,status,reason,seconds,warnings,output\nm,f1,failed,worker died,,,\n"
    )
    if rows is not None:
        (out / "m" / "array.csv").write_text("\n".join([HEADER, *rows]) + "\n")
    if rounds is not None:
        record = {"beacons_sha256": "0" * 64, "calibrated": None, "decided": [], "rounds": rounds}
        (out / "m" / "array.json").write_text(json.dumps(record))
    if calibrated is not None:
        (out / "m" / "beacons-calibrated.csv").write_text(calibrated)
    return out


def _page(out: Path) -> str:
    """overview.html of OUT as `rafostrack summary --no-plots` would write it."""
    write_overview(summarise_tree(out), plots=False)
    return (out / OVERVIEW_HTML).read_text()


def _section(page: str) -> str:
    """The array section's HTML (from its heading to the next heading)."""
    assert TITLE in page
    return page.split(f"<h2>{TITLE}</h2>")[1].split("<h2>")[0]


def _text(fragment: str) -> str:
    """HTML as read: tags dropped, entities read, spaces collapsed."""
    return " ".join(html.unescape(re.sub(r"<[^>]+>", "", fragment)).split())


def test_a_contradicted_value_is_shown_with_its_estimate_and_the_files_are_linked(tmp_path):
    assert HEADER.split(",") == list(ARRAY_COLUMNS)  # the rows here are array.csv's as written
    out = _tree(tmp_path / "out", [CONTRADICTED, UNDETERMINED, CLOCK, *CONSISTENT], calibrated=CALIBRATED)
    (out / "m" / "array.png").write_bytes(b"\x89PNG not really")
    page = _page(out)
    section = _section(page)
    rows = re.findall(r"<tr[^>]*>.*?</tr>", section.split('<table class="array">')[1])
    cells = [[_text(c) for c in re.findall(r"<t[dh][^>]*>(.*?)</t[dh]>", r)] for r in rows]
    assert cells[0] == ["source", "field", "given", "estimated", "sd", "unit", "outcome", "floats", "arrivals"]
    assert cells[1] == ["B1", "offset_s", "300.0", "902.396", "1.536", "s", "contradicted", "9", "716.4"]
    assert cells[2][:2] == ["B2", "position"] and cells[2][3] == "-58.1305 -98.0192 (4.79 km away)"
    assert cells[2][4] == "3.5 km" and cells[2][6] == "undetermined"
    assert cells[3][:2] == ["B1", "clock_s"] and cells[3][6] == "contradicted"
    assert len(rows) == 4  # the consistent values are only counted
    assert "3 of 5 values not consistent with the arrivals" in _text(section)
    line = _text(section.split("<p>")[1])
    assert line.startswith("2 rounds; in the last, 12 floats fit the array, their weighted rms residual 1.23 s")
    assert "decided in beacons-calibrated.csv: B1 offset_s 300.0 → 902.396 s; settled" in line
    for name in ("beacons-calibrated.csv", "array.png", "array.csv"):
        assert f'<a href="m/{name}">{name}</a>' in section
    assert "data:image" not in section  # array.png is linked, not inlined
    assert "Array fit: 1 table value decided." in page.split("</strong>")[0]


def test_the_arrivals_set_aside_are_counted_in_the_rounds_line(tmp_path):
    rounds = [{**ROUNDS[-1], "set_aside": ["f03 B1", "f07 B2"]}]
    line = _text(_section(_page(_tree(tmp_path / "out", CONSISTENT, rounds=rounds))).split("<p>")[1])
    assert "2 float's arrivals of a source set aside as outliers among its floats (array.json)" in line


def test_an_all_consistent_array_says_so_in_one_line(tmp_path):
    page = _page(_tree(tmp_path / "out", CONSISTENT))
    section = _section(page)
    assert '<table class="array">' not in section
    assert "All 2 values are consistent with the arrivals." in _text(section)
    assert "no table value decided" in _text(section)
    assert "beacons-calibrated.csv" not in section and '<a href="m/array.csv">' in section
    assert "no array.png (the batch ran with --no-plots)" in _text(section)
    assert "Array fit: no table value decided." in page.split("</strong>")[0]


def test_a_decided_value_is_shown_as_the_calibrated_table_holds_it(tmp_path):
    """After the last round the floats keep the table of the round before: the line gives
    the table's value (not the last round's estimate) and says the array did not settle."""
    rounds = [{**ROUNDS[0], "round": k} for k in (1, 2, 3)]  # none settled
    table = CALIBRATED.replace("902.396", "899.865")
    kept = CONTRADICTED.replace(",902.396,9,", ",899.865,9,")  # array.csv's `calibrated`: the kept table's
    section = _section(_page(_tree(tmp_path / "out", [kept, *CONSISTENT], rounds, table)))
    assert "B1 offset_s 300.0 → 899.865 s" in _text(section)
    assert "not settled after 3 rounds: the floats keep the table of the round before" in _text(section)


def test_a_mission_without_array_csv_has_no_section(tmp_path):
    """Mission n (array.json and array.png, but no array.csv) gets no section; m gets its own."""
    out = _tree(tmp_path / "out", CONSISTENT)
    with open(out / "batch-summary.csv", "a") as fh:
        fh.write("n,f2,failed,worker died,,,\n")
    (out / "n").mkdir()
    (out / "n" / "array.json").write_text(json.dumps({"rounds": ROUNDS}))
    (out / "n" / "array.png").write_bytes(b"\x89PNG")
    page = _page(out)
    assert page.count("The array, as the mission fitted it") == 1 and TITLE in page
    assert "n/array" not in page
    assert "Array fit: no table value decided." in page  # one mission's, not "fits of 2 missions"


@pytest.mark.parametrize(
    "content, why",
    [
        (b"\xff\xfe\x00garbage", "'utf-8' codec can't decode"),
        (b"source,field\nB1,offset_s\n", "no column given, estimated, sd, unit, outcome, floats, arrivals, calibrated"),
    ],
    ids=["not text", "columns missing"],
)
def test_an_unreadable_array_csv_is_one_line_not_a_traceback(tmp_path, content, why):
    out = _tree(tmp_path / "out", [])
    (out / "m" / "array.csv").write_bytes(content)
    result = CliRunner().invoke(main, ["summary", str(out)])
    assert result.exit_code == 0, result.output
    assert "Traceback" not in result.output
    section = _section((out / OVERVIEW_HTML).read_text())
    assert _text(section).startswith("array.csv cannot be read: " + why)
    assert "<table" not in section and "array.png" not in section


def test_an_unreadable_array_json_leaves_the_values_shown(tmp_path):
    out = _tree(tmp_path / "out", [CONTRADICTED, *CONSISTENT], rounds=None)
    (out / "m" / "array.json").write_text("{not json")
    section = _section(_page(out))
    assert "array.json cannot be read: Expecting property name" in _text(section)
    decided = "decided in beacons-calibrated.csv: B1 offset_s 300.0 → 902.396 s"
    assert f"rounds not known: {decided}" in _text(section)
    assert ">902.396<" in section


def test_the_section_escapes_what_it_shows(tmp_path):
    evil = CONTRADICTED.replace("B1", "<b>B1</b>").replace(",s,", ",<i>s</i>,")
    section = _section(_page(_tree(tmp_path / "out", [evil])))
    assert "<b>" not in section and "<i>" not in section
    assert "&lt;b&gt;B1&lt;/b&gt;" in section and "&lt;i&gt;s&lt;/i&gt;" in section
