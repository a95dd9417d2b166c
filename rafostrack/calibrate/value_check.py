"""One table value weighed against the arrivals: its outcome, its run.json entry and its warning.

A `MetadataCheck` is what `metadata_checks` (the timing fit), `launch_check` and
`window_check` say of one value of floats.csv or beacons.csv: the value given, the value
the arrivals support and its sd, and the outcome, *contradicted*, *consistent*,
*undetermined* or *estimated* (`outcome_of`; the rule and its derivation are in
`metadata_checks`' docstring). Its one-line warning, for a contradicted value or one the
table leaves empty, is a `Notice` of kind `METADATA`, so that whoever triages floats reads
the kind, never the wording. `SourceInformation` is what one float's arrivals know of a
source, for a batch to pool over the floats that hear it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

from ..domain import BeaconTable, FloatInfo
from ..errors import Notice, WarningKind

CONSISTENT, CONTRADICTED, UNDETERMINED, ESTIMATED = "consistent", "contradicted", "undetermined", "estimated"
TRACKED_WITH_SUPPORTED = "tracked with the arrivals' value"  # how a contradiction's warning ends
SCHEDULE_FIELDS = ("offset_s", "start", "end")  # a source's schedule in beacons.csv (`source_scan`)
# Each checked field's tolerance: its `[checks]` setting (a fix or a position is a distance
# from the table's, in km).
TOLERANCE_SETTING = {
    "launch_fix": "fix_tolerance_km",
    "end_fix": "fix_tolerance_km",
    "position": "position_tolerance_km",
    "clock_offset_start_s": "clock_tolerance_s",
    "clock_offset_end_s": "clock_tolerance_s",
    "offset_s": "offset_tolerance_s",
    "drift_s_per_day": "drift_tolerance_s_per_day",
}
SOURCE_UNKNOWNS = ("east_km", "north_km", "offset_s", "drift_s_per_day")


@dataclass(frozen=True)
class SourceInformation:
    """What one float's arrivals alone say of a source's corrections x = (east, north
    displacement km, offset at the table's epoch s, drift s/day) from the table's values
    (`at`): the information matrix J and vector h of the Gaussian exp(-x'Jx/2 + h'x), every
    prior of the source taken out and the float's clock offsets marginalised,

        J = J_xx - J_xc J_cc^+ J_cx,    h = h_x - J_xc J_cc^+ h_c.

    J may be singular (a source heard from one bearing fixes only a combination of its
    position and offset); the floats' arrivals are independent, so their J and h add."""

    matrix: tuple[tuple[float, ...], ...]  # (4, 4), in the units of SOURCE_UNKNOWNS
    vector: tuple[float, ...]  # (4,)
    at: tuple[float, float]  # the offset_s and drift_s_per_day the corrections are from

    def as_json(self) -> dict[str, Any]:
        return {"unknowns": list(SOURCE_UNKNOWNS), "matrix": [list(r) for r in self.matrix],
                "vector": list(self.vector), "at": list(self.at)}  # fmt: skip


@dataclass(frozen=True)
class MetadataCheck:
    """One table value against the arrivals (run.json `metadata_checks`, one entry each)."""

    file: str
    line: int | None
    id: str
    field: str
    given: float | str | None  # None: not in the table; a time as ISO 8601 (UTC)
    supported: float | str | None  # the arrivals' value; None: they cannot tell
    sd: float | None
    unit: str
    outcome: str
    used: float | str | None = None  # the value the track used (set once calibration has decided)
    # For the fixes: the positions, given and supported (lat, lon); given and supported
    # above are then 0 and the distance between them (km).
    given_lat_lon: tuple[float, float] | None = None
    supported_lat_lon: tuple[float, float] | None = None
    # Other fields of the same row that would explain the arrivals as well (a source's
    # position, where these arrivals cannot tell it from its offset or drift).
    alternatives: tuple[str, ...] = ()
    # Other sources (ids) whose schedule (offset, start or end: `SCHEDULE_FIELDS`) would
    # explain the arrivals as well (a source scan's finding where these arrivals cannot tell
    # which source's schedule is wrong, `run.method._scanned_schedules`).
    other_sources: tuple[str, ...] = ()
    # For a source's position: what these arrivals know of the source (`SourceInformation`),
    # for a batch to pool over the floats that hear it.
    information: SourceInformation | None = None
    # Where the track could not use the arrivals' value: why, and what the user should do
    # (the warning ends with it instead of "tracked with the arrivals' value"); for a value
    # the table leaves empty, where the arrivals' value holds (the warning names it).
    note: str | None = None

    def as_json(self) -> dict[str, Any]:
        entry = {k: v for k, v in asdict(self).items() if v is not None or k in ("given", "supported", "sd", "line")}
        if self.information is not None:
            entry["information"] = self.information.as_json()
        for empty in ("alternatives", "other_sources"):
            if not entry[empty]:
                del entry[empty]
        return entry

    def warning(self) -> Notice | None:
        """The one-line warning (of kind `METADATA`) of a contradicted value or of one the
        table leaves empty (None otherwise)."""
        where = f"{self.file}: line {self.line}" if self.line is not None else self.file
        if self.given is None and self.outcome in (UNDETERMINED, ESTIMATED):
            told = "the arrivals cannot tell it" if self.outcome == UNDETERMINED else "estimated from the arrivals"
            told += f" {self.note}" if self.note else ""
            return Notice(
                WarningKind.METADATA,
                f"{where}: field '{self.field}' of {self.id} is empty; {told}: "
                f"{_number(self.supported)} {self.unit} (sd {_number(self.sd)} {self.unit})",
            )
        if self.outcome != CONTRADICTED:
            return None
        if self.unit == "time":
            given, supported = str(self.given or "(empty)"), str(self.supported)
        elif self.given_lat_lon is not None and self.supported_lat_lon is not None:
            given = "{:.3f}, {:.3f}".format(*self.given_lat_lon)
            lat, lon = self.supported_lat_lon
            supported = f"{lat:.3f}, {lon:.3f} ({_number(self.supported)} km away, sd {_number(self.sd)} km)"
        else:
            given = f"{_number(self.given)} {self.unit}"
            spread = "" if self.sd is None else f" (sd {_number(self.sd)} {self.unit})"
            supported = f"{_number(self.supported)} {self.unit}{spread}"
        unsure = undecided_note(self.alternatives, self.other_sources)
        return Notice(
            WarningKind.METADATA,
            f"{where}: field '{self.field}' of {self.id}: given {given}; the arrivals support {supported}{unsure}; "
            f"{self.note or TRACKED_WITH_SUPPORTED}",
        )


def undecided_note(alternatives: Sequence[str], other_sources: Sequence[str]) -> str:
    """What else the arrivals would blame as well, for a contradiction's message: ` (or its
    'position' is wrong: ...)`, ` (or the schedule of B4 is wrong, ...: ...)`; empty if nothing."""
    note = ""
    if alternatives:
        named = " or ".join(f"'{a}'" for a in alternatives)
        note += f" (or its {named} is wrong: these arrivals cannot tell which)"
    if other_sources:
        named = " or ".join(other_sources)
        fields = ", ".join(f"'{f}'" for f in SCHEDULE_FIELDS[:-1]) + f" or '{SCHEDULE_FIELDS[-1]}'"
        note += f" (or the schedule of {named} is wrong, its {fields}: these arrivals cannot tell which source's)"
    return note


def z_of(check: MetadataCheck) -> float:
    """How many of the arrivals' sds the table's value lies from theirs (0: cannot tell)."""
    if not isinstance(check.supported, float) or isinstance(check.given, str) or not check.sd:
        return 0.0
    return abs(check.supported - (check.given or 0.0)) / check.sd


def warnings_of(checks: tuple[MetadataCheck, ...] | list[MetadataCheck]) -> list[Notice]:
    """The warnings of `checks`, one line each (`METADATA` notices)."""
    return [w for w in (c.warning() for c in checks) if w is not None]


def _number(value: float | str | None) -> str:
    return "?" if value is None else value if isinstance(value, str) else f"{value:.4g}"


def outcome_of(correction: float, sd_d: float, tolerance: float, z: float) -> str:
    """Contradicted, undetermined or consistent (the rule: `metadata_checks`' docstring)."""
    if abs(correction) > max(z * sd_d, tolerance):
        return CONTRADICTED
    if sd_d > tolerance or abs(correction) > tolerance + 2.0 * sd_d:
        return UNDETERMINED
    return CONSISTENT


def float_source(info: FloatInfo) -> tuple[str, int | None]:
    """The file and line of the float's row in its table, for a check's message."""
    return info.source if info.source is not None else ("floats.csv", None)


def beacon_source(beacons: BeaconTable, row: int) -> tuple[str, int | None, str]:
    """The file, line and id of a source's row in its table, for a check's message."""
    line = None if beacons.source_line is None else int(beacons.source_line[row])
    return beacons.source_file or "beacons.csv", line, str(beacons.beacon_id[row])
