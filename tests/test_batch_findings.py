"""The batch's metadata findings: the `metadata_checks` of every float's run.json gathered per
mission into one finding per contradicted table value (one per source for beacons.csv, one
per float for floats.csv), `metadata-findings.csv` and the lines printed at the end.

Synthetic output trees (run.json files written here) for the aggregation; one tiny simulated
mission (1 float, 6 days, 60 particles) through `rafostrack batch` end to end.
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner
from support import simulated_mission_dir

from rafostrack import batch as b
from rafostrack.batch.findings import (
    FINDINGS_COLUMNS,
    FINDINGS_NAME,
    LINEAR_LIMIT_KM,
    batch_findings,
    findings_csv,
    median_value,
    mission_findings,
    pooled_check,
)
from rafostrack.batch.report import report_findings
from rafostrack.batch.run import LEGACY_SUPPORTED_NAME
from rafostrack.batch.run_checks import parse_checks
from rafostrack.calibrate.metadata_checks import MetadataCheck, SourceInformation
from rafostrack.cli import main
from rafostrack.model.geodesy import displace

BEACONS = "/data/dimes/beacons.csv"
FLOATS = "/data/dimes/floats.csv"


def _entry(
    file: str, line: int | None, id_: str, field: str, given: Any, supported: Any, outcome: str, unit: str = "s"
):
    return {
        "file": file,
        "line": line,
        "id": id_,
        "field": field,
        "given": given,
        "supported": supported,
        "sd": 0.5,
        "unit": unit,
        "outcome": outcome,
        "used": supported,
    }


def _offset(supported: float, outcome: str, file: str = BEACONS) -> dict[str, Any]:
    """Source B3's offset_s (line 5 of beacons.csv, given 120 s) as one float checked it."""
    return _entry(file, 5, "B3", "offset_s", 120.0, supported, outcome)


def _clock(float_id: str, line: int, given: float, supported: float, outcome: str) -> dict[str, Any]:
    return _entry(FLOATS, line, float_id, "clock_offset_end_s", given, supported, outcome)


def _checks(float_id: str, *entries: dict[str, Any]):
    return parse_checks({"float_id": float_id, "metadata_checks": list(entries)}, float_id)


def _tree(out: Path, runs: dict[tuple[str, str], dict[str, Any] | str], status: str = b.PROCESSED) -> list:
    """OUT/<mission>/<float>/run.json for each run (a dict, or raw text), and their outcomes."""
    outcomes = []
    for (mission, float_id), run in sorted(runs.items()):
        where = out / mission / float_id
        where.mkdir(parents=True)
        (where / "run.json").write_text(run if isinstance(run, str) else json.dumps(run))
        reason = "unchanged" if status == b.SKIPPED else "new"
        outcomes.append(b.FloatOutcome(mission, float_id, status, reason, output=str(where)))
    return outcomes


def _run(float_id: str, *entries: dict[str, Any]) -> dict[str, Any]:
    return {"float_id": float_id, "warnings": [], "warning_kinds": [], "metadata_checks": list(entries)}


# --------------------------------------------------------------------------------------


def test_a_source_contradicted_on_three_floats_is_one_finding():
    """Source B3's offset is heard by four floats, three of which contradict it (one of them
    tracked from another copy of the mission: the file's directory differs), and not by a
    fifth: one finding, k = 3 of n = 4, the median of the three supported values."""
    checks = [
        *_checks("float701", _offset(90.2, "contradicted")),
        *_checks("float702", _offset(95.0, "contradicted", file="/old/root/dimes/beacons.csv")),
        *_checks("float703", _offset(88.0, "contradicted")),
        *_checks("float704", _offset(119.5, "consistent")),
        *_checks("float705", _clock("float705", 6, 1.0, 1.1, "consistent")),
    ]
    [finding] = mission_findings("dimes", checks)
    assert (finding.id, finding.field, finding.line, finding.given) == ("B3", "offset_s", 5, 120.0)
    assert finding.of_source and finding.supported == 90.2
    assert finding.contradicting == ("float701", "float702", "float703")
    assert (finding.n_checked, finding.n_consistent) == (4, 1)
    assert finding.message() == (
        "mission dimes: beacons.csv line 5: field 'offset_s' of source B3: given 120.0 s; "
        "the arrivals support 90.2 s on 3 of 4 floats that hear it (float701, float702, float703)"
    )


def test_a_minority_contradiction_says_so_and_long_lists_are_cut():
    checks = [*_checks("f0", _offset(30.0, "contradicted"))]
    checks += [c for i in range(1, 9) for c in _checks(f"f{i}", _offset(120.0, "consistent"))]
    [weak] = mission_findings("dimes", checks)
    assert weak.message().endswith("the arrivals support 30.0 s on 1 of 9 floats that hear it (f0)")
    many = [c for i in range(7) for c in _checks(f"f{i}", _offset(90.0 + i, "contradicted"))]
    [strong] = mission_findings("dimes", many)
    assert strong.supported == 93.0
    assert strong.message().endswith("93.0 s on 7 of 7 floats that hear it (f0, f1, f2, f3, f4, ...)")
    assert strong.row()["contradicting_floats"] == "f0;f1;f2;f3;f4;f5;f6"


def test_what_the_floats_arrivals_would_blame_as_well_is_named_once_for_the_source():
    """Two floats contradict source B3's offset; each one's arrivals would blame as well
    another source's schedule (a scan's finding) or B3's position: the finding names every
    one of them, once, in its line and in the CSV."""
    first = {**_offset(90.0, "contradicted"), "other_sources": ["B4"], "alternatives": ["lat"]}
    second = {**_offset(91.0, "contradicted"), "other_sources": ["B7", "B4"]}
    [finding] = mission_findings("dimes", [*_checks("f1", first), *_checks("f2", second)])
    assert (finding.alternatives, finding.other_sources) == (("lat",), ("B4", "B7"))
    assert finding.message() == (
        "mission dimes: beacons.csv line 5: field 'offset_s' of source B3: given 120.0 s; the arrivals support "
        "90.5 s (or its 'lat' is wrong: these arrivals cannot tell which) (or the schedule of B4 or B7 is "
        "wrong, its 'offset_s', 'start' or 'end': these arrivals cannot tell which source's) on 2 of 2 floats "
        "that hear it (f1, f2)"
    )
    assert (finding.row()["alternatives"], finding.row()["other_sources"]) == ("lat", "B4;B7")


def test_floats_table_findings_are_one_per_float():
    checks = [
        *_checks("float767", _clock("float767", 4, -12.0, 11.8, "contradicted"), _offset(120.0, "consistent")),
        *_checks("float768", _clock("float768", 5, 3.0, -3.1, "contradicted")),
        *_checks("float769", _clock("float769", 6, 1.0, 1.2, "consistent")),
    ]
    findings = mission_findings("dimes", checks)
    assert [(f.id, f.line, f.contradicting, f.n_checked, f.of_source) for f in findings] == [
        ("float767", 4, ("float767",), 1, False),
        ("float768", 5, ("float768",), 1, False),
    ]
    assert findings[0].message() == (
        "mission dimes: floats.csv line 4: field 'clock_offset_end_s' of float767: given -12.0 s; "
        "the arrivals support 11.8 s"
    )


def test_consistent_undetermined_and_missing_checks_give_no_finding(tmp_path):
    runs: dict[tuple[str, str], dict[str, Any] | str] = {
        ("m", "f1"): _run(
            "f1",
            _offset(119.0, "consistent"),
            _entry(FLOATS, 2, "f1", "clock_offset_end_s", None, 1.5, "estimated"),
            _entry(FLOATS, 2, "f1", "launch_fix", 0.0, None, "undetermined", unit="km"),
        ),
        ("m", "f2"): {"float_id": "f2", "warnings": []},  # an older run.json: no key, no checks
        ("m", "f3"): _run("f3", {"file": BEACONS, "outcome": "contradicted"}),  # no id or field: left out
    }
    assert parse_checks({"float_id": "f2", "warnings": []}, "f2") == []
    findings, unreadable = batch_findings(_tree(tmp_path, runs))
    assert findings == [] and unreadable == []
    assert findings_csv(findings) == ",".join(FINDINGS_COLUMNS) + "\n"


def test_findings_read_the_checks_never_the_warnings(tmp_path):
    """The findings come from `metadata_checks` alone: the same checks with their warnings
    worded otherwise (or of other kinds, or none) give the same findings."""
    entries = (_offset(90.2, "contradicted"), _clock("f1", 2, -12.0, 11.8, "contradicted"))
    said = {
        "today": ["beacons.csv: line 5: field 'offset_s' of B3: given 120 s; the arrivals support 90.2 s"],
        "reworded": ["B3 is early"],
    }
    found = {}
    for name, warnings in said.items():
        run = {**_run("f1", *entries), "warnings": warnings, "warning_kinds": ["metadata"]}
        found[name] = batch_findings(_tree(tmp_path / name, {("m", "f1"): run}))[0]
    none = batch_findings(_tree(tmp_path / "none", {("m", "f1"): {**_run("f1", *entries), "warnings": []}}))[0]
    assert len(found["today"]) == 2
    assert [f.row() for f in found["reworded"]] == [f.row() for f in found["today"]] == [f.row() for f in none]


def test_the_source_is_told_from_the_float_by_file_name_or_id():
    """beacons.csv / floats.csv by name; a table of another name: the float's own id or not."""
    own = _entry("/m/table.csv", 3, "f1", "window_s", 4200.0, 4300.0, "contradicted")
    other = _entry("/m/table.csv", 4, "B2", "drift_s_per_day", 0.0, 0.035, "contradicted", unit="s/day")
    source, mine = sorted(mission_findings("m", _checks("f1", own, other)), key=lambda f: f.id)
    assert source.of_source and not mine.of_source
    assert "given 0.0000 s/day; the arrivals support 0.0350 s/day on 1 of 1 floats" in source.message()
    no_line = _entry(FLOATS, None, "f1", "window_s", 4200.0, None, "contradicted")
    [finding] = mission_findings("m", _checks("f1", no_line))
    assert (
        finding.message()
        == "mission m: floats.csv: field 'window_s' of f1: given 4200.0 s; the arrivals support unknown"
    )


def test_a_source_position_gives_the_median_position():
    """A position (a fix, a source): given 0 and the distance in km, with the positions."""

    def position(supported_km: float, lat: float, lon: float) -> dict[str, Any]:
        entry = _entry(BEACONS, 3, "B1", "position", 0.0, supported_km, "contradicted", unit="km")
        return {**entry, "given_lat_lon": [-58.0, -90.0], "supported_lat_lon": [lat, lon]}

    seen = [position(30.0, -58.25, -90.1), position(33.0, -58.3, -90.2), position(29.0, -58.2, -90.0)]
    [finding] = mission_findings("m", [c for i, e in enumerate(seen) for c in _checks(f"f{i}", e)])
    assert (finding.given_lat_lon, finding.supported_lat_lon, finding.supported) == (
        (-58.0, -90.0),
        (-58.25, -90.1),
        30.0,
    )
    assert finding.message() == (
        "mission m: beacons.csv line 3: field 'position' of source B1: given -58.000, -90.000; "
        "the arrivals support -58.250, -90.100 (30.0 km away) on 3 of 3 floats that hear it (f0, f1, f2)"
    )
    row = finding.row()
    assert (row["given_lat"], row["supported_lon"], row["supported_median"]) == (-58.0, -90.1, 30.0)


def test_the_median_of_times_is_a_time():
    end = "2010-06-01T00:00:00Z"
    assert median_value(["2010-03-01T00:00:00Z", "2010-01-01T00:00:00Z", "2010-02-01T00:00:00Z"]) == (
        "2010-02-01T00:00:00Z"
    )
    assert median_value(["2010-01-01T00:00:00Z", "2010-01-03T00:00:00"]) == "2010-01-02T00:00:00Z"
    assert median_value([None, 2.0, 4.0]) == 3.0 and median_value([None]) is None
    checks = [
        c
        for i, t in enumerate(["2010-07-20T00:00:00Z", "2010-07-10T00:00:00Z", "2010-07-12T00:00:00Z"])
        for c in _checks(f"f{i}", _entry(BEACONS, 7, "B1", "end", end, t, "contradicted", unit="time"))
    ]
    [finding] = mission_findings("m", checks)
    assert finding.message().startswith(
        "mission m: beacons.csv line 7: field 'end' of source B1: given 2010-06-01T00:00:00Z; "
        "the arrivals support 2010-07-12T00:00:00Z on 3 of 3 floats"
    )


def test_batch_findings_read_current_outputs_per_mission(tmp_path):
    """Floats processed now and floats skipped as unchanged count, per mission; a failed
    float's old outputs do not; an unreadable run.json is reported, not fatal."""
    processed = _tree(
        tmp_path,
        {
            ("dimes", "f1"): _run("f1", _offset(90.0, "contradicted")),
            ("other", "f1"): _run("f1", _offset(100.0, "contradicted")),
            ("other", "f9"): "{truncated",
        },
    )
    skipped = _tree(tmp_path, {("dimes", "f2"): _run("f2", _offset(92.0, "contradicted"))}, status=b.SKIPPED)
    failed = _tree(tmp_path, {("dimes", "f3"): _run("f3", _offset(10.0, "contradicted"))}, status=b.FAILED)
    not_yet = [b.FloatOutcome("dimes", "f4", b.SKIPPED, "no arrival file f4.csv (listed in floats.csv)")]
    findings, unreadable = batch_findings([*processed, *skipped, *failed, *not_yet])
    assert [(f.mission, f.contradicting, f.supported) for f in findings] == [
        ("dimes", ("f1", "f2"), 91.0),
        ("other", ("f1",), 100.0),
    ]
    assert len(unreadable) == 1 and "other/f9/run.json: cannot be read" in unreadable[0]


CHECKS = {"z_score": 5.0, "offset_tolerance_s": 5.0, "drift_tolerance_s_per_day": 0.015, "position_tolerance_km": 10.0}


def _configured(float_id: str, *entries: dict[str, Any]) -> list:
    """The checks of a run whose config holds the [checks] settings (as run.json does)."""
    run = {"float_id": float_id, "config": {"checks": CHECKS}, "metadata_checks": list(entries)}
    return parse_checks(run, float_id)


def _drift(supported: float, sd: float, outcome: str) -> dict[str, Any]:
    entry = _entry(BEACONS, 6, "B4", "drift_s_per_day", 0.0, supported, outcome, unit="s/day")
    return {**entry, "sd": sd}


def test_a_source_drift_no_float_is_sure_of_is_found_on_their_arrivals_together():
    """Four floats each put B4's drift 0.03 s/day from the table's 0 with sd 0.008 (3.75 sd:
    undetermined alone); pooled by inverse variance: 0.03 (sd 0.004), 7.5 sd and twice the
    tolerance: contradicted, a finding with no float contradicting it."""
    checks = [c for k in range(4) for c in _configured(f"f{k}", _drift(0.03, 0.008, "undetermined"))]
    (finding,) = mission_findings("dimes", checks)
    assert finding.contradicting == () and finding.n_checked == 4
    assert (finding.pooled.value, finding.pooled.sd, finding.pooled.outcome) == (0.03, 0.004, "contradicted")
    assert finding.supported == 0.03
    assert finding.message() == (
        "mission dimes: beacons.csv line 6: field 'drift_s_per_day' of source B4: given 0.0000 s/day; the arrivals "
        "of the 4 floats that hear it support 0.0300 s/day (sd 0.0040 s/day) together (none alone is sure)"
    )
    row = finding.row()
    assert (row["pooled"], row["pooled_sd"], row["pooled_outcome"], row["n_contradicted"]) == (
        0.03, 0.004, "contradicted", 0
    )  # fmt: skip


def test_the_pool_weighs_each_float_by_its_precision_and_stays_quiet_within_the_tolerance():
    """Values 0.02 (sd 0.005) and 0.0 (sd 0.01): pooled (0.02 x 40000 + 0) / 50000 = 0.016,
    sd 50000^-1/2 = 0.00447; within 0.015 + 2 sd: consistent. Two floats at 0.03 (sd 0.0099):
    0.03 (sd 0.007), beyond 0.015 + 2 sd but under 5 sd: undetermined. Neither is a finding."""
    two = [*_configured("f0", _drift(0.02, 0.005, "undetermined")), *_configured("f1", _drift(0.0, 0.01, "consistent"))]
    pooled = pooled_check(two)
    assert pooled is not None and (pooled.value, pooled.sd, pooled.outcome) == (0.016, 0.00447, "consistent")
    leaning = [c for k in range(2) for c in _configured(f"f{k}", _drift(0.03, 0.0099, "undetermined"))]
    pooled = pooled_check(leaning)
    assert pooled is not None and (pooled.value, pooled.sd, pooled.outcome) == (0.03, 0.007, "undetermined")
    assert mission_findings("dimes", two) == [] and mission_findings("dimes", leaning) == []


def test_a_float_own_value_and_a_source_position_without_information_are_never_pooled():
    clock = _entry(FLOATS, 4, "f0", "clock_offset_end_s", 0.0, 30.0, "undetermined")
    position = {**_entry(BEACONS, 5, "B3", "position", 0.0, 40.0, "undetermined", unit="km"), "sd": 1.0}
    checks = [*_configured("f0", clock, position), *_configured("f1", position)]
    assert mission_findings("dimes", checks) == []


SOURCE_AT = (-64.0, -60.0)  # B3's table position
SOUND_KM_S = 1.5


def _heard_from(
    bearing_deg: float, shift: np.ndarray, rng: np.random.Generator, at: tuple[float, float] = (120.0, 0.0)
):
    """A float hearing B3 from one bearing for 200 days: each arrival moves by -u.(east,
    north) / c + o + d t (t days from the epoch) plus 1 s noise, u the unit vector from the
    source towards the float; its position check as run.json holds it, with the arrivals'
    information (J, h) on the corrections from `at` (one bearing: J of rank 2, a constant and
    a trend)."""
    u = np.array([np.sin(np.radians(bearing_deg)), np.cos(np.radians(bearing_deg))])
    days = np.linspace(0.0, 200.0, 150)
    design = np.column_stack([np.tile(-u / SOUND_KM_S, (len(days), 1)), np.ones_like(days), days])
    toa_shift = design @ shift + rng.normal(0.0, 1.0, len(days))
    info = SourceInformation(tuple(map(tuple, design.T @ design)), tuple(design.T @ toa_shift), at)
    check = MetadataCheck(BEACONS, 5, "B3", "position", 0.0, None, None, "km", "undetermined",
                          given_lat_lon=SOURCE_AT, information=info)  # fmt: skip
    return check.as_json(), design, toa_shift


def test_a_source_position_no_float_can_check_is_found_by_floats_at_other_bearings():
    """B3 sits 25 km from its table position (15 km east, 20 km south). Three floats hear it
    from bearings 30, 150 and 270 degrees; each alone cannot tell a displacement across its
    bearing, or along it from an offset. Their information pooled equals the least-squares
    fit of all their arrivals together (the oracle, on the stacked design): contradicted,
    one finding for the source at the position the arrivals support."""
    rng = np.random.default_rng(5)
    shift = np.array([15.0, -20.0, 0.0, 0.0])
    floats = [_heard_from(bearing, shift, rng) for bearing in (30.0, 150.0, 270.0)]
    assert all(np.linalg.matrix_rank(np.array(e["information"]["matrix"])) == 2 for e, _, _ in floats)
    checks = [c for k, (entry, _, _) in enumerate(floats) for c in _configured(f"f{k}", entry)]

    design = np.vstack([d for _, d, _ in floats])
    fitted, *_ = np.linalg.lstsq(design, np.concatenate([t for _, _, t in floats]), rcond=None)
    cov = np.linalg.inv(design.T @ design)
    distance = np.hypot(*fitted[:2])
    direction = fitted[:2] / distance
    lat, lon = displace(np.array(SOURCE_AT[0]), np.array(SOURCE_AT[1]), *fitted[:2])

    (finding,) = mission_findings("dimes", checks)
    pooled = finding.pooled
    assert pooled is not None and pooled.outcome == "contradicted" and finding.contradicting == ()
    assert pooled.value == round(distance, 2) and abs(distance - 25.0) < 3.0
    assert pooled.sd == round(float(np.sqrt(direction @ cov[:2, :2] @ direction)), 2)
    assert pooled.lat_lon == (round(float(lat), 4), round(float(lon), 4)) == finding.supported_lat_lon
    assert finding.message() == (
        f"mission dimes: beacons.csv line 5: field 'position' of source B3: given -64.000, -60.000; the arrivals "
        f"of the 3 floats that hear it support {lat:.3f}, {lon:.3f} ({distance:.1f} km away, sd {pooled.sd:.1f} km) "
        "together (none alone is sure)"
    )
    assert mission_findings("dimes", checks[:1]) == []  # one float's arrivals alone: nothing to pool


def test_a_pool_beyond_the_linear_model_is_undetermined():
    """The same floats with B3 500 km off: the arrivals' information is linear in the
    displacement only near the table's position, so the pool says nothing (undetermined,
    no finding) rather than a position it cannot vouch for."""
    rng = np.random.default_rng(5)
    shift = np.array([300.0, -400.0, 0.0, 0.0])
    checks = [
        c for k, b in enumerate((30.0, 150.0, 270.0)) for c in _configured(f"f{k}", _heard_from(b, shift, rng)[0])
    ]
    pooled = pooled_check(checks)
    assert pooled is not None and pooled.value > LINEAR_LIMIT_KM and pooled.outcome == "undetermined"
    assert mission_findings("dimes", checks) == []


def test_floats_checked_against_another_offset_pool_on_the_same_corrections():
    """A float whose run used another offset for B3 (a rescheduled source: its corrections
    run from 150 s, not 120 s) adds the same information, shifted: the pool is unchanged."""
    shift = np.array([15.0, -20.0, 0.0, 0.0])
    same = [_heard_from(b, shift, np.random.default_rng(7))[0] for b in (30.0, 150.0, 270.0)]
    moved_entry, _, _ = _heard_from(270.0, shift - np.array([0.0, 0.0, 30.0, 0.0]), np.random.default_rng(7),
                                    at=(150.0, 0.0))  # fmt: skip
    moved = [*same[:2], moved_entry]
    pools = [
        pooled_check([c for k, e in enumerate(entries) for c in _configured(f"f{k}", e)]) for entries in (same, moved)
    ]
    assert pools[0] is not None and pools[1] is not None
    assert pools[0].value == pytest.approx(pools[1].value, abs=0.011)
    assert pools[0].lat_lon == pytest.approx(pools[1].lat_lon, abs=1e-4)


def test_the_csv_and_the_printed_lines(tmp_path):
    outcomes = _tree(
        tmp_path,
        {
            ("dimes", "float767"): _run(
                "float767", _clock("float767", 4, -12.0, 11.8, "contradicted"), _offset(90.0, "contradicted")
            ),
            ("dimes", "float768"): _run("float768", _offset(91.0, "undetermined")),
        },
    )
    stream = io.StringIO()
    reporter = b.Reporter(stream, tty=False)
    text = findings_csv(report_findings(reporter, outcomes, tmp_path))
    rows = list(csv.DictReader(io.StringIO(text)))
    assert tuple(rows[0]) == FINDINGS_COLUMNS
    assert rows == [
        {
            "mission": "dimes",
            "file": BEACONS,
            "line": "5",
            "id": "B3",
            "field": "offset_s",
            "unit": "s",
            "given": "120.0",
            "supported_median": "90.0",
            "given_lat": "",
            "given_lon": "",
            "supported_lat": "",
            "supported_lon": "",
            "n_contradicted": "1",
            "n_checked": "2",
            "n_consistent": "0",
            "contradicting_floats": "float767",
            "pooled": "",  # these runs name no [checks] settings: nothing to judge a pool by
            "pooled_sd": "",
            "pooled_outcome": "",
            "alternatives": "",
            "other_sources": "",
        },
        {
            "mission": "dimes",
            "file": FLOATS,
            "line": "4",
            "id": "float767",
            "field": "clock_offset_end_s",
            "unit": "s",
            "given": "-12.0",
            "supported_median": "11.8",
            "given_lat": "",
            "given_lon": "",
            "supported_lat": "",
            "supported_lon": "",
            "n_contradicted": "1",
            "n_checked": "1",
            "n_consistent": "0",
            "contradicting_floats": "float767",
            "pooled": "",  # these runs name no [checks] settings: nothing to judge a pool by
            "pooled_sd": "",
            "pooled_outcome": "",
            "alternatives": "",
            "other_sources": "",
        },
    ]
    assert stream.getvalue().splitlines() == [
        "rafostrack batch: metadata findings: 2 table value(s) contradicted by the arrivals "
        f"({tmp_path / FINDINGS_NAME}):",
        "rafostrack batch: mission dimes: beacons.csv line 5: field 'offset_s' of source B3: given 120.0 s; "
        "the arrivals support 90.0 s on 1 of 2 floats that hear it (float767)",
        "rafostrack batch: mission dimes: floats.csv line 4: field 'clock_offset_end_s' of float767: "
        "given -12.0 s; the arrivals support 11.8 s",
    ]
    assert len(reporter.lines) == 3  # and batch.log gets them


# --------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def archive(tmp_path_factory) -> Path:
    """A tiny simulated mission `dimes` (one float, sim1, 6 days, 60 particles)."""
    root = tmp_path_factory.mktemp("findings") / "archive"
    simulated_mission_dir(root / "dimes", seed=5, days=6, particles=60)
    return root


def _batch(root: Path, out: Path):
    return CliRunner().invoke(
        main, ["batch", str(root), "--out", str(out), "--no-plots", "--jobs", "1", "--no-array-fit"]
    )


def test_batch_writes_the_findings_atomically_and_reads_unchanged_floats(archive, tmp_path, atomic_writes):
    """A clean mission gives a header-only metadata-findings.csv, written atomically; a float
    skipped as unchanged is read from disk (its run.json edited here, the manifest's size with it)."""
    out = tmp_path / "out"
    result = _batch(archive, out)
    assert result.exit_code == 0, result.output
    assert out / FINDINGS_NAME in atomic_writes
    assert (out / FINDINGS_NAME).read_text() == ",".join(FINDINGS_COLUMNS) + "\n"
    assert not list(out.glob(".*.tmp"))
    assert "metadata findings: no table value contradicted" in (out / "batch.log").read_text()

    float_dir = out / "dimes" / "sim1"
    run = json.loads((float_dir / "run.json").read_text())
    run["metadata_checks"] = [
        _entry(str(archive / "dimes" / "beacons.csv"), 2, "B1", "offset_s", 0.0, 30.5, "contradicted")
    ]
    (float_dir / "run.json").write_text(json.dumps(run))
    manifest = json.loads((float_dir / b.MANIFEST).read_text())
    manifest["files"]["run.json"] = (float_dir / "run.json").stat().st_size
    (float_dir / b.MANIFEST).write_text(json.dumps(manifest))
    stale = out / "dimes" / LEGACY_SUPPORTED_NAME  # an earlier version's table of the floats' findings
    stale.write_text("id,offset_s\nB1,30.5\n")

    result = _batch(archive, out)
    assert result.exit_code == 0, result.output
    assert "1 skipped (1 unchanged)" in result.output
    line = (
        "mission dimes: beacons.csv line 2: field 'offset_s' of source B1: given 0.0 s; "
        "the arrivals support 30.5 s on 1 of 1 floats that hear it (sim1)"
    )
    assert f"rafostrack batch: {line}" in result.stderr
    [row] = list(csv.DictReader((out / FINDINGS_NAME).open()))
    assert (row["mission"], row["id"], row["contradicting_floats"]) == ("dimes", "B1", "sim1")
    # One float's finding is reported, never written into a table (the mission's array fit
    # decides the table, and --no-array-fit asks for none); an earlier version's is removed.
    assert not stale.exists() and not list((out / "dimes").glob("beacons-*.csv"))
