"""The beacon table the arrivals support: a mission's `beacons.csv` with the values its
findings decide replaced, written as `OUT/<mission>/beacons-supported.csv` for the user to
review and track with.

A finding (`findings.Finding`) decides a source's value when the mission's floats agree
that the table is wrong: their arrivals together contradict it (`pooled`), or more than
half of the floats that checked it do (one float of two may have blamed the source for
what is wrong in its own track). It is left to the user, not written, when the
arrivals cannot tell which source's value is wrong (`other_sources`), and a source's offset
or drift is left alone where the same source's position is decided (a displaced source
shifts its arrivals like a wrong offset or drift: the position explains them). The value
written is the pooled one where the pool contradicts the table, else the median over the
contradicting floats.

One value per mission at a time, the strongest (the most floats agreeing, then the pooled
value's distance from the table in its sds): a wrong value pulls the floats' fits and with
them their checks of other sources, whose findings are its echoes (docs/decisions.md).
Tracked with the corrected table, the floats' next findings give the next value, as
calibration releases a float's contradicted values one at a time.

The table is the user's own text with only those cells changed (the same columns, rows,
comments and line ends; a column the table lacks is added, empty on the other rows).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path, PurePath

from ..calibrate.metadata_checks import CONTRADICTED
from ..io.table_text import NotTheRow, with_cells
from .findings import Finding, Pooled, table_place

SUPPORTED_NAME = "beacons-supported.csv"
_TIMING = ("offset_s", "drift_s_per_day")
_DIGITS = {"offset_s": 3, "drift_s_per_day": 5, "lat": 4, "lon": 4}


def decided(finding: Finding) -> bool:
    """Whether the mission's floats agree that the source's table value is wrong (module
    docstring), and on which source."""
    if not finding.of_source or PurePath(finding.file).name != "beacons.csv" or finding.other_sources:
        return False
    return _contradicting_pool(finding) is not None or _most_floats(finding)


def _contradicting_pool(finding: Finding) -> Pooled | None:
    """The finding's pool where it contradicts the table."""
    return finding.pooled if finding.pooled is not None and finding.pooled.outcome == CONTRADICTED else None


def _most_floats(finding: Finding) -> bool:
    """Whether more than half of the floats that checked the value contradict it."""
    return 2 * len(finding.contradicting) > finding.n_checked


def to_correct(findings: Sequence[Finding]) -> list[Finding]:
    """The findings whose values the supported table replaces: per mission the strongest
    decided one (module docstring)."""
    chosen = [f for f in findings if decided(f) and supported_cells(f)]
    moved = {(f.mission, f.id) for f in chosen if f.field == "position"}
    chosen = [f for f in chosen if not (f.field in _TIMING and (f.mission, f.id) in moved)]
    strongest: dict[str, Finding] = {}
    for finding in chosen:
        if finding.mission not in strongest or strength(finding) > strength(strongest[finding.mission]):
            strongest[finding.mission] = finding
    return [f for f in chosen if strongest[f.mission] is f]


def strength(finding: Finding) -> tuple[bool, float]:
    """How sure the mission's floats are: whether most of them contradict the value, then
    its pooled correction in sds (0 without a contradicting pool)."""
    pooled, z = _contradicting_pool(finding), 0.0
    if pooled is not None and pooled.sd > 0:
        given = finding.given if isinstance(finding.given, float) else 0.0  # a position's: 0, its value the distance
        z = abs(pooled.value - given) / pooled.sd
    return _most_floats(finding), z


def supported_cells(finding: Finding) -> dict[str, str]:
    """The columns and texts a finding writes into its row (none when it has no value)."""
    pooled = _contradicting_pool(finding)
    if finding.field == "position":
        lat_lon = pooled.lat_lon if pooled is not None else finding.supported_lat_lon
        if lat_lon is None:
            return {}
        return {"lat": f"{lat_lon[0]:.{_DIGITS['lat']}f}", "lon": f"{lat_lon[1]:.{_DIGITS['lon']}f}"}
    value = pooled.value if pooled is not None else finding.supported
    if finding.field in _TIMING and isinstance(value, float):
        return {finding.field: f"{value:.{_DIGITS[finding.field]}f}"}
    if finding.field in ("start", "end") and isinstance(value, str):
        return {finding.field: value}
    return {}


def supported_table(text: str, findings: Sequence[Finding]) -> str:
    """`text` (a beacons.csv) with each finding's cells (`supported_cells`) in the row of
    its line; ValueError when that line is not the finding's source's row (the table
    changed since the floats were tracked)."""
    edits = [((f.line or 0), f.id, supported_cells(f)) for f in findings]
    try:
        return with_cells(text, edits)
    except NotTheRow as error:
        wrong = findings[error.index]
        raise ValueError(f"{table_place(wrong.file, wrong.line)} is not the row of source {wrong.id}") from None


def write_supported_tables(
    findings: Sequence[Finding], beacons_of: dict[str, Path], out: Path, log: Callable[[str], None]
) -> list[Path]:
    """For each mission (`beacons_of`: mission name -> its beacons.csv) with values to
    correct, OUT/<mission>/beacons-supported.csv, written atomically, with a line to `log`;
    an old one is removed where there is none now (or the table changed since its floats
    were tracked, which `log` is told). The files written."""
    from ..io.atomic import write_text_atomic

    chosen = to_correct(findings)
    written = []
    for mission, beacons in sorted(beacons_of.items()):
        path = Path(out) / mission / SUPPORTED_NAME
        mine = [f for f in chosen if f.mission == mission]
        path.unlink(missing_ok=True)
        if not mine:
            continue
        try:
            with open(beacons, encoding="utf-8", newline="") as table:  # its own line ends
                text = supported_table(table.read(), mine)
        except (OSError, ValueError) as error:
            log(f"mission {mission}: no {SUPPORTED_NAME}: {error}")
            continue
        write_text_atomic(path, text)
        written.append(path)
        log(
            f"mission {mission}: {path}: {beacons.name} with the {len(mine)} value(s) its floats' arrivals decide "
            f"({', '.join(f'{f.id} {f.field}' for f in mine)}); review it and track with it in place of {beacons.name}"
        )
    return written
