"""Metadata faults: wrong or missing values in floats.csv and beacons.csv.

The stress generator (`rafostrack.sim.stress`) writes the tables a careful user would; these
functions write what a careless or unlucky one would. The truth (tracks, arrival times) is
never changed, only what the tables say. Each fault is an `InjectedFault` that the mission
records in `truth/faults.json`:

  end_clock_missing  floats.csv clock_offset_end_s left empty
  clock_sign         clock_offset_end_s written with the wrong sign (only where the true end
                     offset is at least `MIN_SIGN_FLIP_S` from 0: the flip moves it >= 20 s)
  clock_offset       clock_offset_end_s off by 20-40 s (either sign)
  launch_fix         the launch fix 30-60 km off (random bearing)
  end_fix            the end fix 30-60 km off (random bearing)
  window_length      window_s 20-50% too long or too short (to the second): a float's
                     listening window taken from another mission's settings
  source_position    one source's position 20-40 km off (random bearing)
  source_offset      one source's offset_s off by 20-40 s (either sign)
  source_slot        one source's offset_s off by one transmission slot: the spacing of the
                     geometry's schedule (`Geometry.slot_s`: DIMES transmits at 01:05, 01:15,
                     ..., 01:45, every 600 s; the Weddell array at 00:30, 00:35, 00:40, ...,
                     every 300 s; see rafostrack/data/*_sound_sources.csv), towards whichever
                     side keeps the offset inside the window
  source_drift       one source's drift_s_per_day off by 0.02-0.05 s/day (either sign)
  source_active      one source's period 20-60 days shorter than its true active period: the
                     table says it started that long after the mission's start, or ended
                     that long before its end (it transmits while the table says it is off);
                     at most half the mission's days

The clock faults only mean something when the true clock drifted: a stress mission with a
clock fault needs `StressConfig.clock_end_offset_s` (checked there). Float faults apply to
every float of the mission that has the value (a float that never surfaced has no end fix
and no end clock), each with probability `float_share`, the clock kinds given together
sharing the floats (one per float, they write the same field); source faults pick one of the
`candidates` (sources heard by the mission's floats), a different one per kind while there
are enough, the same for every float of the mission.

A fault is named by a run when its `run.json` "metadata_checks" hold an entry with outcome
"contradicted" for the fault's file, id and one of `naming_fields(fault)`; any other
contradicted entry is a false alarm. A source's fault can only be named on a float that
stored enough of the source's signals where the fault acts (`observable`).
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..calibrate.metadata_checks import SCHEDULE_FIELDS
from ..domain import BeaconTable, FloatInfo, NaT
from ..io.csv_table import time_text
from ..model.geodesy import displace

FLOAT_KINDS = ("end_clock_missing", "clock_sign", "clock_offset", "launch_fix", "end_fix", "window_length")
SOURCE_KINDS = ("source_position", "source_offset", "source_slot", "source_drift", "source_active")
FAULT_KINDS = FLOAT_KINDS + SOURCE_KINDS
CLOCK_KINDS = ("end_clock_missing", "clock_sign", "clock_offset")

CLOCK_OFFSET_S = (20.0, 40.0)
FIX_KM = (30.0, 60.0)
WINDOW_SHARE = (0.2, 0.5)
SOURCE_POSITION_KM = (20.0, 40.0)
SOURCE_OFFSET_S = (20.0, 40.0)
SOURCE_DRIFT_S_PER_DAY = (0.02, 0.05)
SOURCE_ACTIVE_DAYS = (20, 60)
MIN_SIGN_FLIP_S = 10.0
MIN_OBSERVED = 10  # a float shows a source's fault where it stored this many of its signals (`observable`)

FLOATS_CSV, BEACONS_CSV = "floats.csv", "beacons.csv"
DAY = np.timedelta64(86400, "s").astype("timedelta64[ns]")

Value = float | tuple[float, float] | str | None


@dataclass(frozen=True)
class InjectedFault:
    """One wrong value: which table, row (`id`: float_id or beacon_id) and field, the value
    the table should hold and the one written (None: empty; fixes and positions as (lat, lon)
    in degrees; times as ISO strings)."""

    kind: str
    file: str
    id: str
    field: str
    true: Value
    written: Value

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict (pairs as lists)."""
        return {k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(self).items()}

    @classmethod
    def from_json(cls, entry: dict[str, Any]) -> InjectedFault:
        """The fault of a `to_json` dict."""

        def value(v: Any) -> Value:
            return (float(v[0]), float(v[1])) if isinstance(v, list) else v

        return cls(entry["kind"], entry["file"], str(entry["id"]), entry["field"], value(entry["true"]),
                   value(entry["written"]))  # fmt: skip


@dataclass(frozen=True)
class SourceSetting:
    """What the source faults need to know of the mission: its schedule's slot spacing, the
    window length (s) and the period the floats listened (start, end)."""

    slot_s: float
    window_s: float
    period: tuple[np.datetime64, np.datetime64]


def check_kinds(kinds: Iterable[str]) -> tuple[str, ...]:
    """`kinds` in `FAULT_KINDS` order, each known (ValueError naming the unknown ones)."""
    kinds = tuple(kinds)
    unknown = sorted(set(kinds) - set(FAULT_KINDS))
    if unknown:
        raise ValueError(f"unknown fault kind(s): {', '.join(unknown)}; known: {', '.join(FAULT_KINDS)}")
    return tuple(k for k in FAULT_KINDS if k in kinds)


def naming_fields(fault: InjectedFault) -> tuple[str, ...]:
    """The metadata_checks fields that name `fault` (source_active: start or end)."""
    return ("start", "end") if fault.kind == "source_active" else (fault.field,)


# --------------------------------------------------------------------------------------
# Drawing faults


def _iso(t: np.datetime64) -> str | None:
    """`t` as the tables write it (`io.csv_table.time_text`), None for an empty time."""
    return None if np.isnat(t) else time_text(t)


def _moved(lat: float, lon: float, km: tuple[float, float], rng: np.random.Generator) -> tuple[float, float]:
    """(lat, lon) moved by a distance uniform in `km` on a uniform bearing, to 6 decimals."""
    r, a = rng.uniform(*km), rng.uniform(0.0, 2 * np.pi)
    mlat, mlon = displace(lat, lon, r * math.sin(a), r * math.cos(a))
    return round(float(mlat), 6), round(float(mlon), 6)


def _signed(span: tuple[float, float], rng: np.random.Generator) -> float:
    """A value uniform in `span`, of random sign."""
    return float(rng.uniform(*span) * rng.choice([-1.0, 1.0]))


def float_fault(kind: str, info: FloatInfo, rng: np.random.Generator) -> InjectedFault | None:
    """`kind` on one float's row, or None where the float lacks the value (no end fix, no end
    clock, or an end offset too small to flip). Draws the same numbers whatever the outcome."""
    shift = _signed(CLOCK_OFFSET_S, rng)
    launch = _moved(info.launch_lat, info.launch_lon, FIX_KM, rng)
    end = _moved(info.end_lat, info.end_lon, FIX_KM, rng) if info.has_end_fix else _moved(0.0, 0.0, FIX_KM, rng)
    clock = info.clock_offset_end_s
    has_clock = info.has_end_fix and not math.isnan(clock)

    def fault(field: str, true: Value, written: Value) -> InjectedFault:
        return InjectedFault(kind, FLOATS_CSV, info.float_id, field, true, written)

    if kind == "launch_fix":
        return fault("launch_fix", (info.launch_lat, info.launch_lon), launch)
    if kind == "end_fix":
        return fault("end_fix", (info.end_lat, info.end_lon), end) if info.has_end_fix else None
    if kind == "window_length":
        return fault("window_s", info.window_s, float(round(info.window_s * (1.0 + _signed(WINDOW_SHARE, rng)))))
    if not has_clock:
        return None
    if kind == "end_clock_missing":
        return fault("clock_offset_end_s", clock, None)
    if kind == "clock_sign":
        return fault("clock_offset_end_s", clock, -clock) if abs(clock) >= MIN_SIGN_FLIP_S else None
    if kind == "clock_offset":
        return fault("clock_offset_end_s", clock, round(clock + shift, 2))
    raise ValueError(f"not a float fault kind: {kind!r}")


def source_fault(
    kind: str, beacons: BeaconTable, beacon_id: str, setting: SourceSetting, rng: np.random.Generator
) -> InjectedFault:
    """`kind` on one source's row of `beacons`."""
    i = list(beacons.beacon_id).index(beacon_id)

    def fault(field: str, true: Value, written: Value) -> InjectedFault:
        return InjectedFault(kind, BEACONS_CSV, beacon_id, field, true, written)

    lat, lon = float(beacons.lat[i]), float(beacons.lon[i])
    offset, drift = float(beacons.offset_s[i]), float(beacons.drift_s_per_day[i])
    if kind == "source_position":
        return fault("position", (lat, lon), _moved(lat, lon, SOURCE_POSITION_KM, rng))
    if kind == "source_offset":
        return fault("offset_s", offset, round(offset + _signed(SOURCE_OFFSET_S, rng), 2))
    if kind == "source_slot":
        step = setting.slot_s * rng.choice([-1.0, 1.0])
        if not 0.0 <= offset + step < setting.window_s:
            step = -step
        return fault("offset_s", offset, float(offset + step))
    if kind == "source_drift":
        return fault("drift_s_per_day", drift, round(drift + _signed(SOURCE_DRIFT_S_PER_DAY, rng), 4))
    if kind == "source_active":
        first, last = setting.period
        days = min(int(rng.integers(SOURCE_ACTIVE_DAYS[0], SOURCE_ACTIVE_DAYS[1] + 1)), int((last - first) / DAY) // 2)
        if rng.random() < 0.5:
            return fault("start", _iso(beacons.start[i]), _iso(first + days * DAY))
        return fault("end", _iso(beacons.end[i]), _iso(last - days * DAY))
    raise ValueError(f"not a source fault kind: {kind!r}")


def draw_faults(
    kinds: Iterable[str],
    beacons: BeaconTable,
    floats: Sequence[FloatInfo],
    candidates: Sequence[str],
    setting: SourceSetting,
    rng: np.random.Generator,
    float_share: float = 1.0,
) -> list[InjectedFault]:
    """The faults of `kinds` (in `FAULT_KINDS` order): float kinds on each float with
    probability `float_share` (the clock kinds, which write the same field, share the floats:
    each float gets one of them, at random), source kinds each on one of `candidates`
    (distinct while there are enough). The tables are not changed (`apply_faults` does)."""
    kinds = check_kinds(kinds)
    clock_kinds = [k for k in kinds if k in CLOCK_KINDS]
    clock_kind = [clock_kinds[int(rng.integers(len(clock_kinds)))] if clock_kinds else None for _ in floats]
    faults: list[InjectedFault] = []
    for kind in (k for k in kinds if k in FLOAT_KINDS):
        for k, info in enumerate(floats):
            chosen = rng.random() < float_share and (kind == clock_kind[k] or kind not in CLOCK_KINDS)
            fault = float_fault(kind, info, rng)
            if chosen and fault is not None:
                faults.append(fault)
    source_kinds = [k for k in kinds if k in SOURCE_KINDS]
    if source_kinds and not candidates:
        raise ValueError("source faults need at least one candidate source")
    picks = rng.permutation(len(candidates))
    for n, kind in enumerate(source_kinds):
        faults.append(source_fault(kind, beacons, candidates[picks[n % len(picks)]], setting, rng))
    return faults


# --------------------------------------------------------------------------------------
# Applying faults


def _set_float(info: FloatInfo, field: str, value: Value) -> FloatInfo:
    if field == "clock_offset_end_s" and (value is None or isinstance(value, float | int)):
        return dataclasses.replace(info, clock_offset_end_s=float("nan") if value is None else float(value))
    if field == "launch_fix" and isinstance(value, tuple):
        return dataclasses.replace(info, launch_lat=float(value[0]), launch_lon=float(value[1]))
    if field == "end_fix" and isinstance(value, tuple):
        return dataclasses.replace(info, end_lat=float(value[0]), end_lon=float(value[1]))
    if field == "window_s" and isinstance(value, float | int):
        return dataclasses.replace(info, window_s=float(value))
    raise ValueError(f"{FLOATS_CSV}: cannot set field {field!r} to {value!r}")


def _time(value: Value) -> np.datetime64:
    return NaT if value is None else np.datetime64(str(value).rstrip("Z"), "ns")


def _set_beacon(beacons: BeaconTable, i: int, field: str, value: Value) -> BeaconTable:
    if field == "position" and isinstance(value, tuple):
        lat, lon = beacons.lat.copy(), beacons.lon.copy()
        lat[i], lon[i] = value
        return dataclasses.replace(beacons, lat=lat, lon=lon)
    if field in ("offset_s", "drift_s_per_day") and isinstance(value, float | int):
        column = getattr(beacons, field).copy()
        column[i] = value
        return dataclasses.replace(beacons, **{field: column})
    if field in ("start", "end"):
        column = getattr(beacons, field).copy()
        column[i] = _time(value)
        return dataclasses.replace(beacons, **{field: column})
    raise ValueError(f"{BEACONS_CSV}: cannot set field {field!r} to {value!r}")


def apply_faults(
    beacons: BeaconTable, floats: Sequence[FloatInfo], faults: Iterable[InjectedFault], *, value: str = "written"
) -> tuple[BeaconTable, list[FloatInfo]]:
    """The tables with each fault's `value` ("written": the faulted tables; "true": the
    correct ones) in its row and field; the inputs are not changed."""
    out = list(floats)
    index = {info.float_id: k for k, info in enumerate(out)}
    rows = {str(b): i for i, b in enumerate(beacons.beacon_id)}
    for fault in faults:
        v = getattr(fault, value)
        if fault.file == FLOATS_CSV:
            out[index[fault.id]] = _set_float(out[index[fault.id]], fault.field, v)
        else:
            beacons = _set_beacon(beacons, rows[fault.id], fault.field, v)
    return beacons, out


def inject_faults(
    kinds: Iterable[str],
    beacons: BeaconTable,
    floats: Sequence[FloatInfo],
    candidates: Sequence[str],
    setting: SourceSetting,
    rng: np.random.Generator,
    float_share: float = 1.0,
) -> tuple[BeaconTable, list[FloatInfo], list[InjectedFault]]:
    """The faulted tables and the faults (`draw_faults`, then `apply_faults`)."""
    faults = draw_faults(kinds, beacons, floats, candidates, setting, rng, float_share)
    faulted_beacons, faulted_floats = apply_faults(beacons, floats, faults)
    return faulted_beacons, faulted_floats, faults


# --------------------------------------------------------------------------------------
# Scoring a run's metadata checks


def _contradicted(checks: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
    return [c for c in checks if c.get("outcome") == "contradicted"]


def names(check: dict[str, Any], fault: InjectedFault) -> bool:
    """Whether a metadata_checks entry names `fault` (same file, id and field, or a field of
    the same row whose entry names the fault's as its alternative, or a schedule fault
    (`SCHEDULE_FIELDS`) of a source that a schedule finding names among its
    `other_sources`; contradicted, or for a value left empty, reported as estimated or
    undetermined with no value given)."""
    missing = fault.written is None and check.get("given") is None
    fields = [check.get("field"), *check.get("alternatives", ())]
    others = [str(i) for i in check.get("other_sources", ())]
    return (
        (check.get("outcome") == "contradicted" or (missing and check.get("outcome") in ("estimated", "undetermined")))
        and Path(str(check.get("file"))).name == fault.file
        and (
            (fault.id == str(check.get("id")) and any(field in naming_fields(fault) for field in fields))
            or (fault.id in others and _of_schedule(naming_fields(fault)) and _of_schedule(fields))
        )
    )


def _of_schedule(fields: Iterable[Any]) -> bool:
    return any(field in SCHEDULE_FIELDS for field in fields)


def observable(fault: InjectedFault, arrivals: pd.DataFrame) -> bool:
    """Whether a float's stored arrivals (`time`, and the true labels in `beacon_id`) can show
    `fault`: a floats.csv value always; a source's value where the float stored at least
    `MIN_OBSERVED` of the source's signals, in the period the table leaves out for an
    active period written too short (a source a float never stored says nothing of its
    table row)."""
    if fault.file != BEACONS_CSV:
        return True
    mine = arrivals["beacon_id"].astype(str) == fault.id
    if fault.kind == "source_active":
        time = pd.to_datetime(arrivals["time"], utc=True)
        written = pd.Timestamp(str(fault.written))
        if fault.field == "start":  # the true start, None: active from the first window
            mine &= (time < written) & ((time >= pd.Timestamp(str(fault.true))) if fault.true else True)
        else:  # the true end, None: active to the last window
            mine &= (time > written) & ((time <= pd.Timestamp(str(fault.true))) if fault.true else True)
    return int(mine.sum()) >= MIN_OBSERVED


def unnamed_faults(faults: Iterable[InjectedFault], checks: Sequence[dict[str, Any]]) -> list[InjectedFault]:
    """The faults no contradicted entry of `checks` names."""
    return [f for f in faults if not any(names(c, f) for c in checks)]


def false_alarms(faults: Sequence[InjectedFault], checks: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """The contradicted entries of `checks` that name none of `faults`."""
    return [c for c in _contradicted(checks) if not any(names(c, f) for f in faults)]


def read_faults(path: Path) -> list[InjectedFault]:
    """The faults of a `truth/faults.json` (none when the file is absent)."""
    path = Path(path)
    return [InjectedFault.from_json(e) for e in json.loads(path.read_text())] if path.exists() else []
