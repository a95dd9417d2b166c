"""The metadata findings of a batch: which table values the arrivals contradict, per mission.

Each tracked float's `run.json` holds `metadata_checks`: one entry per value the tracker
took from `floats.csv` / `beacons.csv` and checked against the arrivals (`run_checks`). A
batch reads those of every float whose outputs are current (processed in this run, or
skipped as unchanged) and gathers them per mission into one finding per value (file, id,
field) contradicted on at least one float:

- a `beacons.csv` value (a source's offset, drift, position, active period) is heard by
  every float near the source, so a wrong one shows on each of them: it is one finding for
  the source, counting the floats that contradict it (k) and those that checked it (n, any
  outcome); k < n/2 is weak evidence and shows as such ("on 1 of 9 floats");
- a `floats.csv` value belongs to one float: one finding per float.

The supported value of a finding is the median, over the floats that contradict it, of the
value each one's arrivals support (times: the median instant).

A source's offset or drift is also weighed on the floats' arrivals together: each float's
estimate x_k (sd s_k) comes from its own arrivals, independent of the others', so they pool
by inverse variance,

    x = sum(x_k / s_k^2) / sum(1 / s_k^2),    sd = sum(1 / s_k^2)^(-1/2),

and the pooled value is judged by the rule of a float's check (`outcome_of`, with the
tolerance and z-score of the runs' `[checks]`). A value no float alone is sure of, but
their arrivals together contradict, is a finding too (`pooled`: k = 0).

A source's position is pooled in information form: each float's arrivals alone say
(J_k, h_k) of the source's corrections (east, north, offset, drift; a float hearing the
source from one bearing fixes only a combination of them, J_k singular), and floats heard
from other bearings complete each other,

    J = sum J_k,    x = J^-1 sum h_k,    cov = J^-1,

the pooled displacement judged along its direction like a float's (`Pooled.lat_lon`: the
position the arrivals support). The arrivals are linear in the displacement only while it is
small beside the ranges (the range's second-order term is d^2 / 2R across the bearing); a
pool that puts the source farther than `LINEAR_LIMIT_KM` from its table position rests on
directions the floats barely constrain and is undetermined.

Tracks are not redone: a finding says which value to correct in the table before
rerunning (`corrections` writes the table with the strongest one corrected).
"""

from __future__ import annotations

import dataclasses
import statistics
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path, PurePath
from typing import Any

import numpy as np

from ..calibrate.metadata_checks import CONTRADICTED, UNDETERMINED, along_itself, outcome_of, undecided_note
from ..io.writers import csv_text
from ..model.geodesy import displace
from .plan import FAILED, SKIPPED, FloatOutcome
from .run_checks import Check, LatLon, Value, read_run_checks
from .run_checks import parse_checks as parse_checks  # re-exported: callers read run.json checks from here too

FINDINGS_NAME = "metadata-findings.csv"
FINDINGS_COLUMNS = (
    "mission",
    "file",
    "line",
    "id",
    "field",
    "unit",
    "given",
    "supported_median",
    "given_lat",
    "given_lon",
    "supported_lat",
    "supported_lon",
    "n_contradicted",
    "n_checked",
    "n_consistent",
    "contradicting_floats",
    "pooled",
    "pooled_sd",
    "pooled_outcome",
    "alternatives",
    "other_sources",
)
LINEAR_LIMIT_KM = 100.0  # d^2 / 2R: 5 km at a range of 1000 km
_SHOWN_FLOATS = 5  # float ids printed per finding (all of them are in the CSV)
_DIGITS = {"s": 1, "km": 1, "s/day": 4, "deg": 4}


@dataclass(frozen=True)
class Finding:
    """A table value contradicted by the arrivals of at least one float of a mission."""

    mission: str
    file: str
    line: int | None
    id: str
    field: str
    unit: str
    given: Value
    supported: Value  # median over the floats that contradict it
    contradicting: tuple[str, ...]  # their float ids, sorted
    n_checked: int  # floats with an entry for it (any outcome)
    n_consistent: int
    of_source: bool
    given_lat_lon: LatLon = None  # positions (fixes, sources): the table's
    supported_lat_lon: LatLon = None  # and the median latitude and longitude the arrivals support
    pooled: Pooled | None = None  # a source's offset or drift on every float's arrivals together
    alternatives: tuple[str, ...] = ()  # what the contradicting floats' arrivals would blame as well
    other_sources: tuple[str, ...] = ()

    def row(self) -> dict[str, Any]:
        """One row of metadata-findings.csv."""
        return dict(
            mission=self.mission,
            file=self.file,
            line="" if self.line is None else self.line,
            id=self.id,
            field=self.field,
            unit=self.unit,
            given="" if self.given is None else self.given,
            supported_median="" if self.supported is None else self.supported,
            given_lat="" if self.given_lat_lon is None else self.given_lat_lon[0],
            given_lon="" if self.given_lat_lon is None else self.given_lat_lon[1],
            supported_lat="" if self.supported_lat_lon is None else self.supported_lat_lon[0],
            supported_lon="" if self.supported_lat_lon is None else self.supported_lat_lon[1],
            n_contradicted=len(self.contradicting),
            n_checked=self.n_checked,
            n_consistent=self.n_consistent,
            contradicting_floats=";".join(self.contradicting),
            pooled="" if self.pooled is None else self.pooled.value,
            pooled_sd="" if self.pooled is None else self.pooled.sd,
            pooled_outcome="" if self.pooled is None else self.pooled.outcome,
            alternatives=";".join(self.alternatives),
            other_sources=";".join(self.other_sources),
        )

    def message(self) -> str:
        """The line printed at the end of the batch, e.g. `mission dimes: beacons.csv line 5:
        field 'offset_s' of source B3: given 120.0 s; the arrivals support 90.2 s on 7 of 9
        floats that hear it (float701, float702, ...)`."""
        where = table_place(self.file, self.line)
        what = f"field '{self.field}' of {'source ' if self.of_source else ''}{self.id}"
        given, supported = value_texts(self)
        if not self.contradicting and self.pooled is not None:
            value, sd = format_value(self.pooled.value, self.unit), format_value(self.pooled.sd, self.unit)
            pooled = f"{value} (sd {sd})"
            if self.pooled.lat_lon is not None:
                lat, lon = self.pooled.lat_lon
                pooled = f"{lat:.3f}, {lon:.3f} ({value} away, sd {sd})"
            return (
                f"mission {self.mission}: {where}: {what}: given {given}; the arrivals of the {self.n_checked} floats "
                f"that hear it support {pooled} together (none alone is sure)"
            )
        unsure = undecided_note(self.alternatives, self.other_sources)
        text = f"mission {self.mission}: {where}: {what}: given {given}; the arrivals support {supported}{unsure}"
        if not self.of_source:
            return text
        shown = ", ".join(self.contradicting[:_SHOWN_FLOATS])
        more = ", ..." if len(self.contradicting) > _SHOWN_FLOATS else ""
        return f"{text} on {len(self.contradicting)} of {self.n_checked} floats that hear it ({shown}{more})"


def table_place(file: str, line: int | None) -> str:
    """Where a value stands in its table: `beacons.csv line 4` (the file's name only)."""
    return PurePath(file).name + (f" line {line}" if line is not None else "")


def value_texts(value: Check | Finding) -> tuple[str, str]:
    """The given and the supported value of a check or finding as a message shows them
    (`format_value`); a position (a fix, a source) as latitude, longitude, the supported
    one with its distance from the given."""
    given, supported = format_value(value.given, value.unit), format_value(value.supported, value.unit)
    if value.given_lat_lon is not None and value.supported_lat_lon is not None:
        (lat, lon), (lat_d, lon_d) = value.given_lat_lon, value.supported_lat_lon
        given, supported = f"{lat:.3f}, {lon:.3f}", f"{lat_d:.3f}, {lon_d:.3f} ({supported} away)"
    return given, supported


def format_value(value: Value, unit: str) -> str:
    """A value with its unit for a message: `120.0 s`, `0.0350 s/day`; times as written."""
    if value is None:
        return "unknown"
    if isinstance(value, str):
        return value
    digits = _DIGITS.get(unit)
    number = f"{value:.{digits}f}" if digits is not None else f"{value:.6g}"
    return f"{number} {unit}" if unit and unit != "time" else number


def mission_findings(mission: str, checks: Iterable[Check]) -> list[Finding]:
    """One finding per (file name, id, field) contradicted on at least one float, sorted by
    file, line, id and field. Per value: k = floats whose entry is contradicted, n = floats
    with an entry (any outcome but "missing"), supported = median over the k floats."""
    per_float: dict[tuple[str, str, str], dict[str, Check]] = {}
    for check in checks:
        if check.outcome == "missing":
            continue
        seen = per_float.setdefault(check.key, {})
        if check.float_id not in seen or check.outcome == CONTRADICTED:  # a float counts once
            seen[check.float_id] = check
    findings = []
    for by_float in per_float.values():
        pooled = pooled_check(list(by_float.values()))
        if any(c.outcome == CONTRADICTED for c in by_float.values()) or (pooled and pooled.outcome == CONTRADICTED):
            findings.append(_finding(mission, by_float, pooled))
    findings = with_position_named(findings)
    return sorted(findings, key=lambda f: (PurePath(f.file).name, f.line is None, f.line or 0, f.id, f.field))


def with_position_named(findings: list[Finding]) -> list[Finding]:
    """`findings`, a source's offset or drift naming its position as the other explanation
    where the position is a finding too: a displaced source moves its arrivals by -u.d / c
    (an offset while a float's bearing holds, a drift while it turns), so each float alone
    may blame its timing for what the floats together put on its position."""
    moved = {(PurePath(f.file).name, f.id) for f in findings if f.of_source and f.field == "position"}
    return [
        dataclasses.replace(f, alternatives=_union([f.alternatives, ("position",)]))
        if f.field in ("offset_s", "drift_s_per_day") and (PurePath(f.file).name, f.id) in moved
        else f
        for f in findings
    ]


@dataclass(frozen=True)
class Pooled:
    """A source's value on every float's arrivals together (module docstring); a position's
    value is its distance from the table's (km), `lat_lon` the position."""

    value: float
    sd: float
    outcome: str
    lat_lon: LatLon = None


def pooled_check(checks: Sequence[Check]) -> Pooled | None:
    """The pool of the floats' values of one source's offset, drift (inverse variance) or
    position (information form: `pooled_position`); None for other fields, or without a
    float whose check has a value, an sd and its settings."""
    if checks and checks[0].field == "position":
        return pooled_position(checks)
    usable = [c for c in checks if c.of_source and _poolable(c)]
    if not usable or not isinstance(usable[0].given, float):
        return None
    pairs = [(float(c.supported), 1.0 / float(c.sd) ** 2) for c in usable]  # type: ignore[arg-type]  # _poolable
    weight = sum(w for _, w in pairs)
    value, sd = sum(x * w for x, w in pairs) / weight, weight**-0.5
    tolerance, z = float(usable[0].tolerance or 0.0), float(usable[0].z_score or 0.0)
    digits = 3 if usable[0].unit == "s" else 5
    return Pooled(round(value, digits), round(sd, digits), outcome_of(value - usable[0].given, sd, tolerance, z))


def pooled_position(checks: Sequence[Check]) -> Pooled | None:
    """A source's position on every float's arrivals together (module docstring); None
    without two floats' information, settings or a given position, or where the floats
    together do not fix all four corrections (J not positive definite)."""
    usable = [c for c in checks if c.of_source and c.information is not None and c.given_lat_lon is not None]
    usable = [c for c in usable if c.tolerance is not None and c.z_score is not None]
    if len(usable) < 2:
        return None
    at = np.array(usable[0].information.at)  # type: ignore[union-attr]  # filtered above
    matrix, vector = np.zeros((4, 4)), np.zeros(4)
    for check in usable:
        info = check.information
        j_k = np.array(info.matrix)  # type: ignore[union-attr]
        # Corrections from another float's table values (a rescheduled source): x = x_k + (at_k - at).
        shift = np.concatenate([[0.0, 0.0], np.array(info.at) - at])  # type: ignore[union-attr]
        matrix += j_k
        vector += np.array(info.vector) + j_k @ shift  # type: ignore[union-attr]
    matrix = 0.5 * (matrix + matrix.T)
    if np.linalg.eigvalsh(matrix).min() <= 1e-12 * max(1.0, float(np.abs(matrix).max())):
        return None
    cov = np.linalg.inv(matrix)
    shift_km = (cov @ vector)[:2]
    distance, sd = along_itself(shift_km, cov[:2, :2])
    tolerance, z = float(usable[0].tolerance), float(usable[0].z_score)  # type: ignore[arg-type]
    lat, lon = displace(np.array(usable[0].given_lat_lon[0]), np.array(usable[0].given_lat_lon[1]), *shift_km)  # type: ignore[index]
    lat_lon = (round(float(lat), 4), round(float(lon), 4))
    outcome = outcome_of(distance, sd, tolerance, z) if distance <= LINEAR_LIMIT_KM else UNDETERMINED
    return Pooled(round(distance, 2), round(sd, 2), outcome, lat_lon)


def _poolable(check: Check) -> bool:
    """A value, an sd and the settings to judge a pool by (`parse_checks` sets a tolerance
    only for the pooled fields, `run_checks.POOLED_TOLERANCE`)."""
    return (
        isinstance(check.supported, float)
        and check.sd is not None
        and check.sd > 0
        and check.tolerance is not None
        and check.z_score is not None
    )


def _finding(mission: str, by_float: Mapping[str, Check], pooled: Pooled | None = None) -> Finding:
    """The finding of one table value from each float's check of it (and their pool)."""
    against = [by_float[f] for f in sorted(by_float) if by_float[f].outcome == CONTRADICTED]
    first = against[0] if against else by_float[sorted(by_float)[0]]
    return Finding(
        mission=mission,
        file=first.file,
        line=first.line,
        id=first.id,
        field=first.field,
        unit=first.unit,
        given=first.given,
        supported=median_value([c.supported for c in against]) if against or pooled is None else pooled.value,
        contradicting=tuple(c.float_id for c in against),
        n_checked=len(by_float),
        n_consistent=sum(c.outcome == "consistent" for c in by_float.values()),
        of_source=first.of_source,
        given_lat_lon=first.given_lat_lon,
        supported_lat_lon=_median_lat_lon([c.supported_lat_lon for c in against])
        if against or pooled is None
        else pooled.lat_lon,
        pooled=pooled,
        alternatives=_union(c.alternatives for c in against),
        other_sources=_union(c.other_sources for c in against),
    )


def _union(names: Iterable[tuple[str, ...]]) -> tuple[str, ...]:
    """The names of every float's entry, each once, sorted."""
    return tuple(sorted({name for some in names for name in some}))


def _median_lat_lon(positions: Sequence[LatLon]) -> LatLon:
    """The median latitude and the median longitude (a source's position seen from several floats)."""
    known = [p for p in positions if p is not None]
    if not known:
        return None
    return (float(statistics.median(p[0] for p in known)), float(statistics.median(p[1] for p in known)))


def median_value(values: Sequence[Value]) -> Value:
    """The median of numbers, or of ISO times (an odd count gives the middle time as written);
    None when there is none. Numbers and times mixed: the numbers."""
    numbers = [v for v in values if isinstance(v, float)]
    if numbers:
        return float(statistics.median(numbers))
    times = sorted((when, v) for v in values if isinstance(v, str) and (when := _instant(v)) is not None)
    if not times:
        return next((v for v in values if v is not None), None)
    middle = len(times) // 2
    if len(times) % 2:
        return times[middle][1]
    early, late = times[middle - 1][0], times[middle][0]
    return _iso(early + (late - early) / 2)


def _instant(text: str) -> datetime | None:
    """An ISO time (naive ones taken as UTC), or None when the text is not one."""
    try:
        when = datetime.fromisoformat(text)
    except ValueError:
        return None
    return when if when.tzinfo is not None else when.replace(tzinfo=UTC)


def _iso(when: datetime) -> str:
    text = when.isoformat(timespec="seconds")
    return text[:-6] + "Z" if text.endswith("+00:00") else text


def batch_findings(outcomes: Sequence[FloatOutcome]) -> tuple[list[Finding], list[str]]:
    """The findings of every mission, from the run.json of each float whose outputs are
    current (processed now or skipped as unchanged; a failed float's old outputs are not),
    and a line for each run.json that could not be read."""
    checks: dict[str, list[Check]] = {}
    unreadable = []
    for outcome in outcomes:
        if not is_current(outcome):
            continue
        path = Path(outcome.output) / "run.json"
        read = read_run_checks(path, outcome.float_id)
        if read is None:
            unreadable.append(f"{path}: cannot be read; its metadata checks are left out of {FINDINGS_NAME}")
            continue
        checks.setdefault(outcome.mission, []).extend(read)
    findings = [f for mission in sorted(checks) for f in mission_findings(mission, checks[mission])]
    return findings, unreadable


def is_current(outcome: FloatOutcome) -> bool:
    """Whether the float's output directory holds outputs of its current inputs."""
    if outcome.status == FAILED or not outcome.output:
        return False
    return outcome.status != SKIPPED or outcome.reason == "unchanged"


def findings_csv(findings: Sequence[Finding]) -> str:
    """The text of metadata-findings.csv: a header (`FINDINGS_COLUMNS`) and one row per finding."""
    return csv_text(FINDINGS_COLUMNS, (finding.row() for finding in findings))
