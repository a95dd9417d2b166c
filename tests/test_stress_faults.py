"""Metadata faults in the stress scenario (`rafostrack.sim.faults`, `StressConfig.faults`): each
kind changes only its field, by the stated amount, and is recorded in the truth; the truth is
the same with and without faults; the default scenario writes the files it always wrote."""

from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from rafostrack.model.geodesy import range_m
from rafostrack.sim.faults import (
    CLOCK_KINDS,
    FAULT_KINDS,
    InjectedFault,
    apply_faults,
    false_alarms,
    observable,
    read_faults,
    unnamed_faults,
)
from rafostrack.sim.stress import (
    FAULT_STREAM,
    StressConfig,
    StressMission,
    simulate_stress,
    substream,
    with_faults,
    write_stress_mission,
)
from rafostrack.sim.stress_world import GEOMETRIES

DRIFTING = StressConfig(days=130, eddies=False, clock_end_offset_s=(-40.0, 40.0), never_surfaced_share=0.25)
SEED = 23  # one float never surfaced, one end clock too close to 0 to flip

# What each kind changes (file, columns) and by how much (the fault module's ranges).
CHANGES = {
    "end_clock_missing": ("floats.csv", {"clock_offset_end_s"}),
    "clock_sign": ("floats.csv", {"clock_offset_end_s"}),
    "clock_offset": ("floats.csv", {"clock_offset_end_s"}),
    "launch_fix": ("floats.csv", {"launch_lat", "launch_lon"}),
    "end_fix": ("floats.csv", {"end_lat", "end_lon"}),
    "window_length": ("floats.csv", {"window_s"}),
    "source_position": ("beacons.csv", {"lat", "lon"}),
    "source_offset": ("beacons.csv", {"offset_s"}),
    "source_slot": ("beacons.csv", {"offset_s"}),
    "source_drift": ("beacons.csv", {"drift_s_per_day"}),
    "source_active": ("beacons.csv", {"start", "end"}),
}


def _digest(root: Path) -> str:
    h = hashlib.sha256()
    for path in sorted(Path(root).rglob("*")):
        if path.is_file():
            h.update(str(path.relative_to(root)).encode())
            h.update(path.read_bytes())
    return h.hexdigest()


@pytest.fixture(scope="module")
def correct(tmp_path_factory: pytest.TempPathFactory) -> tuple[StressMission, np.random.Generator, Path]:
    """A DIMES mission of 4 floats with drifting clocks (one never surfaced), written."""
    rng = np.random.default_rng(SEED)
    mission = simulate_stress("dimes", 4, rng, DRIFTING)
    root = tmp_path_factory.mktemp("correct")
    write_stress_mission(mission, root)
    return mission, rng, root


def _table(root: Path, name: str) -> pd.DataFrame:
    return pd.read_csv(root / name, dtype=str, keep_default_na=False).set_index(name.split("s.")[0] + "_id")


def _changed_cells(a: pd.DataFrame, b: pd.DataFrame) -> set[tuple[str, str]]:
    return {(row, col) for col in a.columns for row in a.index if a.at[row, col] != b.at[row, col]}


def _amount_ok(fault: InjectedFault, period: tuple[np.datetime64, np.datetime64]) -> bool:
    true, written = fault.true, fault.written
    if fault.kind == "end_clock_missing":
        return written is None and isinstance(true, float)
    if fault.kind == "clock_sign":
        return isinstance(true, float) and written == -true and abs(true) >= 10.0
    if fault.kind in ("clock_offset", "source_offset"):
        return 20.0 - 0.01 <= abs(float(written) - float(true)) <= 40.0 + 0.01  # type: ignore[arg-type]
    if fault.kind in ("launch_fix", "end_fix", "source_position"):
        km = float(range_m(true[0], true[1], written[0], written[1])) / 1e3  # type: ignore[index]
        low, high = (20.0, 40.0) if fault.kind == "source_position" else (30.0, 60.0)
        return low * 0.995 <= km <= high * 1.005
    if fault.kind == "window_length":
        return 0.2 - 1e-3 <= abs(float(written) / float(true) - 1.0) <= 0.5 + 1e-3  # type: ignore[arg-type]
    if fault.kind == "source_slot":
        return abs(float(written) - float(true)) == GEOMETRIES["dimes"].slot_s  # type: ignore[arg-type]
    if fault.kind == "source_drift":
        return 0.02 - 1e-4 <= abs(float(written) - float(true)) <= 0.05 + 1e-4  # type: ignore[arg-type]
    # source_active: the period 20-60 days shorter, at one end
    at = np.datetime64(str(written).rstrip("Z"), "ns")
    days = (at - period[0] if fault.field == "start" else period[1] - at) / np.timedelta64(1, "D")
    return bool(20 <= days <= 60)


@pytest.mark.parametrize("kind", FAULT_KINDS)
def test_each_fault_changes_only_its_field_by_the_stated_amount_and_is_recorded(kind, correct, tmp_path):
    mission, rng, root = correct
    faulty = with_faults(mission, dataclasses.replace(DRIFTING, faults=(kind,)), substream(rng, FAULT_STREAM))
    write_stress_mission(faulty, tmp_path)
    faults = read_faults(tmp_path / "truth" / "faults.json")
    assert faults == list(faulty.faults or ()) and faults and {f.kind for f in faults} == {kind}
    file, columns = CHANGES[kind]
    other = "beacons.csv" if file == "floats.csv" else "floats.csv"
    assert (tmp_path / other).read_bytes() == (root / other).read_bytes()
    changed = _changed_cells(_table(root, file), _table(tmp_path, file))
    assert {col for _, col in changed} <= columns
    assert {row for row, _ in changed} == {f.id for f in faults}
    period = (
        mission.floats[0].truth["time"].iloc[0].to_datetime64(),
        mission.floats[0].truth["time"].iloc[-1].to_datetime64(),
    )
    assert all(_amount_ok(f, period) for f in faults), faults
    if kind in ("end_fix", *CLOCK_KINDS):  # the float that never surfaced has no end values to fault
        assert not any(
            f.id == info.float_id for f in faults for info in (s.info for s in mission.floats) if not info.has_end_fix
        )
    for path in root.rglob("*"):  # arrivals and truth untouched
        if path.is_file() and path.name not in ("floats.csv", "beacons.csv", "faults.json"):
            assert (tmp_path / path.relative_to(root)).read_bytes() == path.read_bytes()


def test_a_source_fault_hits_one_source_for_every_float_and_the_clock_kinds_share_the_floats(correct):
    mission, rng, _ = correct
    faulty = with_faults(mission, dataclasses.replace(DRIFTING, faults=FAULT_KINDS), substream(rng, FAULT_STREAM))
    faults = list(faulty.faults or ())
    sources = [f for f in faults if f.file == "beacons.csv"]
    assert len(sources) == 5 and len({f.id for f in sources}) == 5  # distinct sources
    clock = [f.id for f in faults if f.field == "clock_offset_end_s"]
    assert len(clock) == len(set(clock))  # one clock fault per float: they write the same field
    beacons, infos = apply_faults(
        *apply_faults(mission.beacons, [f.info for f in mission.floats], faults), faults, value="true"
    )
    assert all(a == b for a, b in zip(infos, (f.info for f in mission.floats), strict=True))
    assert np.array_equal(beacons.offset_s, mission.beacons.offset_s) and np.array_equal(
        beacons.lat, mission.beacons.lat
    )


def test_the_truth_is_the_same_with_and_without_faults():
    cfg = dataclasses.replace(DRIFTING, days=40, never_surfaced_share=0.0)
    plain = simulate_stress("weddell", 2, np.random.default_rng(5), cfg)
    faulty = simulate_stress("weddell", 2, np.random.default_rng(5), dataclasses.replace(cfg, faults=FAULT_KINDS))
    assert plain.faults is None and faulty.faults
    for a, b in zip(plain.floats, faulty.floats, strict=True):
        assert a.truth.equals(b.truth) and a.events == b.events and a.info == b.info
        assert all(
            np.array_equal(x.toa_s, y.toa_s) and x.beacon_id == y.beacon_id
            for x, y in zip(a.record.windows, b.record.windows, strict=True)
        )


def test_the_default_scenario_writes_the_files_it_always_wrote(tmp_path):
    """Digests of missions written before the clock, surfacing and fault knobs existed."""
    expected = {
        ("dimes", 11): "ce2f63b143318d4a4aeb26ca5d4358dfe5247a05e13039b109ee61d2168e2cc4",
        ("weddell", 12): "929a1630123f6305c9767c2a55dd3995391a9040ca0bae43888511d72f868cc1",
    }
    off = {"clock_end_offset_s": None, "never_surfaced_share": 0.0, "faults": ()}
    for (geometry, seed), digest in expected.items():
        for k, cfg in enumerate((StressConfig(days=40, eddies=False), StressConfig(days=40, eddies=False, **off))):
            out = tmp_path / f"{geometry}{k}"
            write_stress_mission(simulate_stress(geometry, 2, np.random.default_rng(seed), cfg), out)
            assert _digest(out) == digest
            assert not (out / "truth" / "faults.json").exists()


def test_same_seed_same_bytes_with_every_knob_on(tmp_path):
    cfg = dataclasses.replace(DRIFTING, days=40, faults=FAULT_KINDS)
    for name in ("a", "b"):
        write_stress_mission(simulate_stress("weddell", 3, np.random.default_rng(8), cfg), tmp_path / name)
    assert _digest(tmp_path / "a") == _digest(tmp_path / "b")


def test_drifting_clocks_are_written_and_floats_that_never_surfaced_have_no_end(correct):
    mission, _, root = correct
    floats = pd.read_csv(root / "floats.csv", dtype=str, keep_default_na=False)
    for sim, row in zip(mission.floats, floats.itertuples(index=False), strict=True):
        _, end_s = sim.events["true_clock_offset_s"]
        if sim.events["surfaced"]:
            assert float(row.clock_offset_end_s) == round(end_s, 2) and -40 <= end_s <= 40
        else:
            assert (row.end_time, row.end_lat, row.end_lon, row.clock_offset_end_s) == ("", "", "", "")
    assert not all(s.events["surfaced"] for s in mission.floats)


def test_clock_faults_need_a_drifting_clock_and_kinds_are_checked():
    with pytest.raises(ValueError, match="need clock_end_offset_s"):
        StressConfig(days=40, faults=("clock_sign",))
    with pytest.raises(ValueError, match="unknown fault kind"):
        StressConfig(days=40, faults=("clock_flip",))
    StressConfig(days=40, faults=("launch_fix", "source_slot"))


def test_a_fault_is_named_by_a_contradicted_check_of_its_file_id_and_field():
    fault = InjectedFault(
        "source_active", "beacons.csv", "W2d", "start", "2008-03-07T00:00:00Z", "2008-05-01T00:00:00Z"
    )
    clock = InjectedFault("clock_sign", "floats.csv", "s01", "clock_offset_end_s", 12.0, -12.0)

    def check(file: str, id_: str, field: str, outcome: str = "contradicted") -> dict:
        return {"file": f"/data/{file}", "id": id_, "field": field, "outcome": outcome}

    checks = [
        check("beacons.csv", "W2d", "end"),  # source_active: start or end names it
        check("floats.csv", "s01", "clock_offset_end_s", "consistent"),
        check("floats.csv", "s01", "launch_fix"),
    ]
    assert unnamed_faults([fault, clock], checks) == [clock]
    assert false_alarms([fault, clock], checks) == [checks[2]]
    assert false_alarms([], []) == [] and unnamed_faults([], checks) == []
    assert json.loads(json.dumps(fault.to_json())) == fault.to_json()
    assert InjectedFault.from_json(fault.to_json()) == fault


def test_a_source_position_fault_is_named_by_an_offset_that_names_the_position_as_its_alternative():
    moved = InjectedFault("source_position", "beacons.csv", "US1-6", "position", [-58.33, -74.41], [-58.09, -74.15])
    offset = {"file": "beacons.csv", "id": "US1-6", "field": "offset_s", "outcome": "contradicted"}
    assert unnamed_faults([moved], [offset]) == [moved]  # an offset alone is another fault
    assert false_alarms([moved], [offset]) == [offset]
    either = {**offset, "alternatives": ["position"]}
    assert unnamed_faults([moved], [either]) == [] and false_alarms([moved], [either]) == []
    wrong_offset = InjectedFault("source_offset", "beacons.csv", "US1-6", "offset_s", 360.0, 390.0)
    assert unnamed_faults([wrong_offset], [either]) == []  # and it still names an offset


def test_a_source_fault_shows_only_on_a_float_that_stored_the_source_s_signals_where_it_acts():
    """`observable`: a floats.csv fault always; a source's where the float stored at least
    `MIN_OBSERVED` of its signals, inside the period the table leaves out for an active
    period written too short."""
    days = pd.date_range("2008-03-01", periods=40, freq="D", tz="UTC")
    arrivals = pd.DataFrame({"time": days.strftime("%Y-%m-%dT%H:%M:%SZ"), "beacon_id": ["W2d"] * 40})
    arrivals.loc[:4, "beacon_id"] = np.nan  # clutter in the first five windows
    offset = InjectedFault("source_offset", "beacons.csv", "W2d", "offset_s", 300.0, 330.0)
    assert observable(offset, arrivals) and not observable(dataclasses.replace(offset, id="W7a"), arrivals)
    late = InjectedFault("source_active", "beacons.csv", "W2d", "start", "2008-03-01T00:00:00Z", "2008-03-19T00:00:00Z")
    assert observable(late, arrivals)  # 13 of its signals before the written start (5 are clutter)
    assert not observable(dataclasses.replace(late, written="2008-03-13T00:00:00Z"), arrivals)  # 7
    early = InjectedFault("source_active", "beacons.csv", "W2d", "end", "2008-04-09T00:00:00Z", "2008-04-01T00:00:00Z")
    assert not observable(early, arrivals)  # 8 after the written end
    assert observable(InjectedFault("launch_fix", "floats.csv", "f1", "launch_fix", (0.0, 0.0), (0.1, 0.0)), arrivals)


def test_a_scan_finding_that_cannot_tell_two_sources_apart_names_the_fault_of_either():
    slot = InjectedFault("source_slot", "beacons.csv", "UK1-1", "offset_s", 1500.0, 2100.0)
    either = {"file": "beacons.csv", "id": "UK1-2", "field": "offset_s", "outcome": "contradicted",
              "other_sources": ["UK1-1"]}  # fmt: skip
    assert unnamed_faults([slot], [either]) == [] and false_alarms([slot], [either]) == []
    alone = {k: v for k, v in either.items() if k != "other_sources"}
    assert unnamed_faults([slot], [alone]) == [slot] and false_alarms([slot], [alone]) == [alone]
    assert false_alarms([], [either]) == [either]  # with right tables, a false alarm all the same


def test_a_scan_finding_names_another_sources_schedule_whichever_field_is_wrong():
    """`other_sources` name other sources whose schedule explains the arrivals as well: an
    active period written to end early is named by another source's offset finding that
    names its source, a drift (not a schedule value) is not."""
    early_end = InjectedFault("source_active", "beacons.csv", "UK1-1", "end", "2010-09-14T00:00:00Z", None)
    drift = InjectedFault("source_drift", "beacons.csv", "UK1-1", "drift_s_per_day", 0.0, 0.05)
    either = {"file": "beacons.csv", "id": "UK1-4", "field": "offset_s", "outcome": "contradicted",
              "other_sources": ["UK1-1"]}  # fmt: skip
    assert unnamed_faults([early_end, drift], [either]) == [drift]
    assert false_alarms([early_end], [either]) == [] and false_alarms([drift], [either]) == [either]
