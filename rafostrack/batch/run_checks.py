"""One float's metadata checks, as its run.json holds them: the entries a batch gathers.

A tracked float's `run.json` holds `metadata_checks`: one entry per value the tracker took
from `floats.csv` / `beacons.csv` and checked against the arrivals (file, line, id, field,
given, supported, sd, unit, outcome, used; for a source's position the arrivals'
information on the source). `parse_checks` reads them into `Check`s, leaving out entries
that do not name their value and reading anything malformed as unknown; a `run.json`
without the key (written by an older version) holds no checks. The batch's findings
(`findings.py`) gather them per mission.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path, PurePath
from typing import Any

import numpy as np

from ..calibrate.metadata_checks import TOLERANCE_SETTING, SourceInformation

# The pooled fields and the [checks] tolerance that judges each.
POOLED_TOLERANCE = {field: TOLERANCE_SETTING[field] for field in ("offset_s", "drift_s_per_day", "position")}

Value = float | str | None
LatLon = tuple[float, float] | None


@dataclass(frozen=True)
class Check:
    """One entry of one float's `metadata_checks`."""

    float_id: str  # the float whose run.json holds it
    file: str  # the path as the run was given it
    line: int | None
    id: str  # float_id (floats.csv) or beacon_id (beacons.csv)
    field: str
    unit: str
    given: Value
    supported: Value
    outcome: str
    given_lat_lon: LatLon = None  # a fix or a source position: given is 0, supported the distance (km)
    supported_lat_lon: LatLon = None
    sd: float | None = None  # the sd of the float's arrivals' value
    tolerance: float | None = None  # the run's [checks] tolerance and z-score for the field
    z_score: float | None = None
    alternatives: tuple[str, ...] = ()  # other fields of the row the arrivals would blame as well
    other_sources: tuple[str, ...] = ()  # other sources whose schedule they would blame as well
    information: SourceInformation | None = None  # a source position's: the float's arrivals on the source

    @property
    def key(self) -> tuple[str, str, str]:
        """What names the table value across floats: file name, id, field (the file's
        directory may differ between floats tracked in different runs)."""
        return (PurePath(self.file).name, self.id, self.field)

    @property
    def of_source(self) -> bool:
        """A beacons.csv value (shared by the floats that hear the source), not the float's own."""
        name = PurePath(self.file).name
        if name in ("beacons.csv", "floats.csv"):
            return name == "beacons.csv"
        return self.id != self.float_id


def parse_checks(run: Mapping[str, Any], float_id: str) -> list[Check]:
    """The `metadata_checks` of one run.json payload (none when the key is missing); entries
    that lack a file, id or field are left out. `float_id` is used when the run names none."""
    entries = run.get("metadata_checks")
    if not isinstance(entries, list):
        return []
    own = str(run.get("float_id") or float_id)
    config = run.get("config")
    settings = config.get("checks") if isinstance(config, Mapping) else None
    settings = settings if isinstance(settings, Mapping) else {}
    checks = []
    for entry in entries:
        if not isinstance(entry, Mapping) or not all(entry.get(k) not in (None, "") for k in ("file", "id", "field")):
            continue
        line = entry.get("line")
        checks.append(
            Check(
                float_id=own,
                file=str(entry["file"]),
                line=line if isinstance(line, int) and not isinstance(line, bool) else None,
                id=str(entry["id"]),
                field=str(entry["field"]),
                unit=str(entry.get("unit") or ""),
                given=_value(entry.get("given")),
                supported=_value(entry.get("supported")),
                outcome=str(entry.get("outcome") or "missing"),
                given_lat_lon=_lat_lon(entry.get("given_lat_lon")),
                supported_lat_lon=_lat_lon(entry.get("supported_lat_lon")),
                sd=number(entry.get("sd")),
                tolerance=number(settings.get(POOLED_TOLERANCE.get(str(entry["field"]), ""))),
                z_score=number(settings.get("z_score")),
                alternatives=_names(entry.get("alternatives")),
                other_sources=_names(entry.get("other_sources")),
                information=_information(entry.get("information")),
            )
        )
    return checks


def _information(value: Any) -> SourceInformation | None:
    """A run.json `information` entry (None when missing or malformed)."""
    if not isinstance(value, Mapping):
        return None
    try:
        matrix = np.asarray(value["matrix"], dtype=float)
        vector = np.asarray(value["vector"], dtype=float)
        at = np.asarray(value["at"], dtype=float)
    except (KeyError, TypeError, ValueError):
        return None
    if matrix.shape != (4, 4) or vector.shape != (4,) or at.shape != (2,):
        return None
    if not (np.isfinite(matrix).all() and np.isfinite(vector).all() and np.isfinite(at).all()):
        return None
    return SourceInformation(tuple(map(tuple, matrix.tolist())), tuple(vector.tolist()), (float(at[0]), float(at[1])))


def number(value: Any) -> float | None:
    """A JSON value as a finite float, None for anything else (missing, text, bool, NaN)."""
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        return None
    return float(value)


def _value(value: Any) -> Value:
    if isinstance(value, bool) or value is None:
        return None
    if isinstance(value, int | float):
        return float(value)
    return str(value)


def _names(value: Any) -> tuple[str, ...]:
    """A JSON list of field or source names (anything else: none)."""
    return tuple(str(v) for v in value) if isinstance(value, list | tuple) else ()


def _lat_lon(value: Any) -> LatLon:
    if not isinstance(value, list | tuple) or len(value) != 2:
        return None
    if not all(isinstance(v, int | float) and not isinstance(v, bool) for v in value):
        return None
    return (float(value[0]), float(value[1]))


def read_run_checks(run_json: Path, float_id: str) -> list[Check] | None:
    """The metadata checks of one float's run.json; None when the file cannot be read."""
    try:
        run = json.loads(Path(run_json).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return parse_checks(run, float_id) if isinstance(run, dict) else None
