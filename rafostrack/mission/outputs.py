"""A mission's array fit written out: `array.csv` (per source and field: the value given, the
mission's estimate and sd, the floats and arrivals it rests on, the outcome, the value the
calibrated table holds; besides the table's values, each source's clock over the mission),
`beacons-calibrated.csv` (the user's beacons.csv with only the decided cells changed) and
`array.png` (`plots.array_residuals`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ..calibrate import kalman
from ..calibrate.metadata_checks import beacon_source
from ..domain import BeaconTable
from ..io.atomic import write_text_atomic
from ..io.table_text import with_cells
from ..io.writers import csv_text
from ..plots.array_residuals import SourcePanel, plot_array_residuals
from .array import MissionArray, changed_values
from .array_checks import CLOCK

ARRAY_NAME = "array.csv"
CALIBRATED_NAME = "beacons-calibrated.csv"
ARRAY_PLOT_NAME = "array.png"
_DIGITS = {"offset_s": 3, "drift_s_per_day": 5, "lat": 4, "lon": 4}


def _text(value: float | str | None, lat_lon: tuple[float, float] | None) -> str:
    if lat_lon is not None:
        return f"{lat_lon[0]:.4f} {lat_lon[1]:.4f}"
    return "" if value is None else str(value)


ARRAY_COLUMNS = ("source", "field", "given", "estimated", "shift", "sd", "unit", "at", "outcome", "calibrated",
                 "floats", "arrivals", "line")  # fmt: skip


def table_cells(table: BeaconTable, row: int, field: str) -> dict[str, str]:
    """A table field's cells of one row (`array.TABLE_FIELDS`; a position is two) as the
    calibrated table writes them."""
    if field == "position":
        return {"lat": f"{table.lat[row]:.{_DIGITS['lat']}f}", "lon": f"{table.lon[row]:.{_DIGITS['lon']}f}"}
    return {field: f"{getattr(table, field)[row]:.{_DIGITS[field]}f}"}


def _clock_time(array: MissionArray, source: int) -> str:
    """When a source's clock is judged: its epoch plus the arrivals' mean days, to the
    minute (UTC); '' for a source without a start (its epoch is each float's launch)."""
    start = array.beacons.start[int(array.fit.layout.sources[source])]
    if np.isnat(start):
        return ""
    minutes = np.timedelta64(round(float(array.fit.layout.mid_days[source]) * 1440.0), "m")
    return str((start + minutes).astype("datetime64[m]"))


def array_rows(array: MissionArray, table: BeaconTable | None = None) -> list[dict[str, Any]]:
    """`array.csv`'s rows: per source and field, given, estimated (the arrivals' value), sd,
    unit, when a clock is judged (`at`), outcome, the value the calibrated table `table`
    holds where it changed it (by default `MissionArray.calibrated_beacons`; the clock is no
    column: its source's offset is), floats and arrivals."""
    table = array.calibrated_beacons() if table is None else table
    changed = changed_values(array.beacons, table)
    rows = []
    for v in array.values:
        c, row = v.check, int(array.fit.layout.sources[v.source])
        held = c.field in changed and bool(changed[c.field][row])
        rows.append(
            {
                "source": c.id,
                "field": c.field,
                "given": _text(c.given, c.given_lat_lon),
                "estimated": _text(c.supported, c.supported_lat_lon),
                "shift": "" if c.field != "position" or c.supported is None else c.supported,
                "sd": "" if c.sd is None else c.sd,
                "unit": "lat lon" if c.field == "position" else c.unit,
                "at": _clock_time(array, v.source) if c.field == CLOCK else "",
                "outcome": c.outcome,
                "calibrated": " ".join(table_cells(table, row, c.field).values()) if held else "",
                "floats": v.floats,
                "arrivals": round(v.arrivals, 1),
                "line": "" if c.line is None else c.line,
            }
        )
    return rows


def calibrated_text(beacons: BeaconTable, table: BeaconTable, given_text: str) -> str:
    """The user's beacons.csv text (`beacons` as read) with the cells `table` changed."""
    changed = changed_values(beacons, table)
    edits = []
    for row in range(len(beacons)):
        cells = {}
        for field, moved in changed.items():
            if moved[row]:
                cells.update(table_cells(table, row, field))
        if cells:
            _, line, name = beacon_source(beacons, row)
            edits.append((line or 0, name, cells))
    return with_cells(given_text, edits)


def source_panels(array: MissionArray) -> list[SourcePanel]:
    """Per source, every float's residuals with the tables as given and after the fit."""
    fit = array.fit
    parts: list[list[tuple]] = [[] for _ in fit.layout.sources]
    for k, f in enumerate(fit.floats):
        at_given = np.zeros(f.problem.n_unknowns)
        lin = kalman.linearise(f.problem, at_given, np.ones(f.n_arrivals), kalman.DEFAULT_PRIORS, array_priors=False)
        where = fit.layout.arrival_sources(f)
        times = f.problem.time[f.problem.node]
        for g in np.unique(where):
            sel = where == g
            parts[g].append((times[sel], np.full(sel.sum(), k), lin.toa_residual_s[sel], fit.toa_residual_s[k][sel]))
    titles = _titles(array)
    return [
        SourcePanel(titles[g], *(np.concatenate(column) for column in zip(*part, strict=True)))
        for g, part in enumerate(parts)
        if part
    ]


def _titles(array: MissionArray) -> list[str]:
    """Each source's id and the values the mission decided for it."""
    names = [str(array.beacons.beacon_id[row]) for row in array.fit.layout.sources]
    for v in array.decided():
        c = v.check
        change = f"{c.supported} km moved" if c.field == "position" else f"{c.given} -> {c.supported} {c.unit}"
        names[v.source] += f"\n{c.field} {change}"
    return names


def write_array_outputs(
    array: MissionArray, out_dir: Path, beacons_path: Path, plots: bool = True, kept: BeaconTable | None = None
) -> list[Path]:
    """`array.csv`, `beacons-calibrated.csv` (when the mission decided a value; an old one is
    removed otherwise; left as it is when `kept`, the table in it, is the one the floats
    keep: it holds the decisions already, `MissionArray.settled_in`, or the last round
    leaves the floats with it; array.csv's `calibrated` then says what it holds) and
    `array.png` in `out_dir`, each written atomically."""
    out_dir.mkdir(parents=True, exist_ok=True)
    calibrated = out_dir / CALIBRATED_NAME
    if kept is not None and calibrated.is_file():
        table = kept
    else:
        table = array.calibrated_beacons()
        if array.decided():
            with open(beacons_path, encoding="utf-8", newline="") as given:  # its own line ends
                write_text_atomic(calibrated, calibrated_text(array.beacons, table, given.read()))
        else:
            calibrated.unlink(missing_ok=True)
    write_text_atomic(out_dir / ARRAY_NAME, csv_text(ARRAY_COLUMNS, array_rows(array, table)))
    written = [out_dir / ARRAY_NAME] + ([calibrated] if calibrated.is_file() else [])
    if plots:
        names = [f.float_id for f in array.fit.floats]
        written.append(plot_array_residuals(out_dir / ARRAY_PLOT_NAME, source_panels(array), names))
    return written
