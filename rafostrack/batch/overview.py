"""The mission overview: which floats of an output tree need a look, in one table and one map.

Written in the output root at the end of every `rafostrack batch` (`run.py`), and by
`rafostrack summary OUT` for an existing tree (a batch output root, or a `rafostrack track
--out` folder): `overview.csv` (one row per float, columns `OVERVIEW_COLUMNS`),
`overview.png` (every track on one map, `plots.mission_map`) and `overview.html` (the map
inline and the table, sorted by a click on a column's header), each written atomically.

Per tracked float, from its outputs: the windows and their shares by `status` of
track.parquet (ok, ambiguous, recovered, unsupported); the median and the 95th percentile of
`sd_km`; the shares of its TOAs labelled to a beacon and called clutter (labels.parquet,
`beacon_id` empty; the two add up to 1); from run.json the sound speed and the TOA sd the
last pass used (calibrated, or as configured), the RMS residual of the calibration's direct
arrivals, the float clock's drift over the record (the end offset used minus the launch
offset used, `metadata_checks`), the warnings counted by kind (`warning_kind`) and the
table values its arrivals contradict (`metadata_checks` read by `findings.parse_checks`).
A float that failed in the batch is listed with its reason; a float not tracked (no arrival
file yet) is only counted.

A float needs a look (`LookRules`; each rule that applies is named in `reasons`) when it
failed, when its outputs cannot be read, when it has no window, when its arrivals contradict
a table value, when the end fix is far from every particle (an `end fix` warning), or when
a share or the sd passes its limit: unsupported windows > 10%, ambiguous > 5%, recovered >
2%, 95th percentile of sd_km > 20 km, clutter > 50% of the TOAs. Order: failed, then needs
a look (more reasons first), then ok; ties by mission and float id.
"""

from __future__ import annotations

import base64
import csv
import dataclasses
import html
import json
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path, PurePath
from typing import Any
from urllib.parse import quote

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from .. import __version__
from ..calibrate.metadata_checks import CONTRADICTED
from ..errors import InputError
from ..io import atomic
from ..plots.mission_map import NEEDS_LOOK, OK, FloatPath, plot_mission_map
from .findings import Check, Finding, batch_findings, is_current, number, parse_checks, table_place, value_texts
from .plan import FAILED, PROCESSED, FloatOutcome

OVERVIEW_HTML = "overview.html"
OVERVIEW_CSV = "overview.csv"
OVERVIEW_PNG = "overview.png"
STATUSES = ("ok", "ambiguous", "recovered", "unsupported")  # track.parquet `status`
OVERVIEW_COLUMNS = (
    "look",
    "mission",
    "float_id",
    "reasons",
    "windows",
    *(f"share_{s}" for s in STATUSES),
    "sd_km_median",
    "sd_km_p95",
    "share_labelled",
    "share_clutter",
    "sound_speed_m_s",
    "sound_speed_calibrated",
    "clock_drift_s",
    "toa_sigma_s",
    "toa_sigma_calibrated",
    "toa_residual_rms_s",
    "n_warnings",
    "warning_kinds",
    "n_contradicted",
    "metadata_contradicted",
    "output",
)
LOOK_ORDER = {FAILED: 0, NEEDS_LOOK: 1, OK: 2}

# A warning's kind: the first whose phrases one is found in the message (else "other").
WARNING_KINDS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("metadata", ("the arrivals support", "the arrivals cannot tell it", "estimated from the arrivals")),
    ("end fix", ("the end fix is",)),
    ("gaps", ("no usable beacon", "no active beacon")),
    ("outlier TOAs", ("sd from every particle's prediction",)),
    ("likelihood", ("likelihood not finite",)),
    ("calibration", ("to calibrate",)),
    ("arrival file", ("duplicate", "outside the window", "more than max_signals", "have both an empty",
                      "open less than window_s")),
    ("memory", ("need about",)),
)  # fmt: skip


@dataclass(frozen=True)
class LookRules:
    """When a float needs a look (module docstring): the limits, each exceeded strictly."""

    unsupported_share_max: float = 0.10
    ambiguous_share_max: float = 0.05
    recovered_share_max: float = 0.02
    sd_km_p95_max: float = 20.0
    clutter_share_max: float = 0.50

    def describe(self) -> list[str]:
        """The rules as sentences, for the page."""
        return [
            "it failed in the batch, or its outputs cannot be read, or it has no window",
            "its arrivals contradict a value of floats.csv or beacons.csv (metadata checks)",
            "its end fix is far from every particle (an 'end fix' warning)",
            f"more than {self.unsupported_share_max:.0%} of its windows are unsupported (drift model only)",
            f"more than {self.ambiguous_share_max:.0%} of its windows are ambiguous (two positions)",
            f"more than {self.recovered_share_max:.0%} of its windows are recovered (the track was lost)",
            f"the 95th percentile of its sd_km is above {self.sd_km_p95_max:g} km",
            f"more than {self.clutter_share_max:.0%} of its TOAs are called clutter",
        ]

    def reasons(self, row: FloatRow) -> list[str]:
        """Why `row`'s float needs a look, one phrase per rule that applies (none: ok)."""
        if row.failed:
            return [f"failed: {row.failed}"]
        if row.unreadable:
            return [f"outputs unreadable: {row.unreadable}"]
        if not row.windows:
            return ["no window tracked"]
        reasons = []
        if row.contradicted:
            reasons.append("arrivals contradict " + "; ".join(what for what, _ in row.contradicted))
        if row.warning_kinds.get("end fix"):
            reasons.append("end fix far from every particle")
        limits = (("unsupported", self.unsupported_share_max), ("ambiguous", self.ambiguous_share_max),
                  ("recovered", self.recovered_share_max))  # fmt: skip
        for status, limit in limits:
            share = row.shares.get(status, 0.0)
            if share > limit:
                reasons.append(f"{status} {share:.1%} of windows > {limit:.0%}")
        if row.sd_km_p95 is not None and row.sd_km_p95 > self.sd_km_p95_max:
            reasons.append(f"p95 sd {row.sd_km_p95:.1f} km > {self.sd_km_p95_max:g} km")
        if row.clutter_share is not None and row.clutter_share > self.clutter_share_max:
            reasons.append(f"clutter {row.clutter_share:.1%} of TOAs > {self.clutter_share_max:.0%}")
        return reasons


@dataclass(frozen=True)
class FloatRow:
    """One float of the overview: what its outputs say, and whether it needs a look."""

    mission: str
    float_id: str
    output: str = ""  # its output directory ("" when it failed)
    failed: str = ""  # the batch's reason, when it failed
    unreadable: str = ""  # why its outputs cannot be read
    windows: int | None = None
    shares: Mapping[str, float] = field(default_factory=dict)  # status -> share of windows
    sd_km_median: float | None = None
    sd_km_p95: float | None = None
    labelled_share: float | None = None
    clutter_share: float | None = None
    sound_speed_m_s: float | None = None
    sound_speed_calibrated: bool | None = None
    clock_drift_s: float | None = None
    toa_sigma_s: float | None = None
    toa_sigma_calibrated: bool | None = None
    toa_residual_rms_s: float | None = None
    warning_kinds: Mapping[str, int] = field(default_factory=dict)
    contradicted: tuple[tuple[str, str], ...] = ()  # per contradicted table value: what, given vs arrivals
    beacons_file: str = ""  # the beacons.csv it was tracked with (run.json), for the map
    lat: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0), repr=False, compare=False)
    lon: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0), repr=False, compare=False)
    look: str = OK
    reasons: tuple[str, ...] = ()

    @property
    def n_warnings(self) -> int:
        return sum(self.warning_kinds.values())

    def contradicted_text(self) -> str:
        """'beacons.csv line 4: offset_s of US1-3: given 1530.0 s, arrivals 1497.2 s; ...'."""
        return "; ".join(f"{what}: {detail}" for what, detail in self.contradicted)

    def row(self) -> dict[str, Any]:
        """One row of overview.csv (shares as fractions; empty where unknown)."""
        known = self.windows is not None and not self.unreadable
        return dict(
            look=self.look,
            mission=self.mission,
            float_id=self.float_id,
            reasons="; ".join(self.reasons),
            windows=_cell(self.windows),
            **{f"share_{s}": _cell(self.shares.get(s, 0.0) if known else None, 4) for s in STATUSES},
            sd_km_median=_cell(self.sd_km_median, 3),
            sd_km_p95=_cell(self.sd_km_p95, 3),
            share_labelled=_cell(self.labelled_share, 4),
            share_clutter=_cell(self.clutter_share, 4),
            sound_speed_m_s=_cell(self.sound_speed_m_s, 2),
            sound_speed_calibrated=_cell(self.sound_speed_calibrated),
            clock_drift_s=_cell(self.clock_drift_s, 3),
            toa_sigma_s=_cell(self.toa_sigma_s, 3),
            toa_sigma_calibrated=_cell(self.toa_sigma_calibrated),
            toa_residual_rms_s=_cell(self.toa_residual_rms_s, 3),
            n_warnings=self.n_warnings if known else "",
            warning_kinds=kinds_text(self.warning_kinds, "=", ";"),
            n_contradicted=len(self.contradicted) if known else "",
            metadata_contradicted=self.contradicted_text(),
            output=self.output,
        )


def _cell(value: float | int | bool | None, digits: int | None = None) -> str | float | int:
    """A CSV cell: empty for None, booleans as true/false, floats rounded to `digits`."""
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if digits is not None and isinstance(value, float):
        return round(value, digits)
    return value


def kinds_text(kinds: Mapping[str, int], sep: str = " ", join: str = ", ") -> str:
    """'metadata 2, gaps 1' (or 'metadata=2;gaps=1' for the CSV), most frequent first."""
    ordered = sorted(kinds.items(), key=lambda kv: (-kv[1], kv[0]))
    return join.join(f"{kind}{sep}{n}" for kind, n in ordered)


@dataclass(frozen=True)
class Overview:
    """The floats of an output tree, in the order shown (needing a look first)."""

    out: Path
    rows: list[FloatRow]
    not_tracked: int = 0  # listed in floats.csv but with no arrival file (or skipped otherwise)
    rules: LookRules = LookRules()
    findings: tuple[str, ...] = ()  # the mission's metadata findings, one line each (`findings.py`)

    def count(self, look: str) -> int:
        return sum(r.look == look for r in self.rows)


# ----------------------------------------------------------------------------- the floats


def warning_kind(message: str) -> str:
    """The kind of one run.json warning (`WARNING_KINDS`; "other" when none matches)."""
    return next((kind for kind, phrases in WARNING_KINDS if any(p in message for p in phrases)), "other")


def track_stats(track: pd.DataFrame) -> dict[str, Any]:
    """Windows, the share of each status among them, the median and 95th percentile of sd_km."""
    n = len(track)
    status = track["status"].astype(str) if "status" in track else pd.Series([], dtype=str)
    counts = status.value_counts()
    sd = pd.to_numeric(track.get("sd_km", pd.Series([], dtype=float)), errors="coerce").to_numpy(dtype=float)
    sd = sd[np.isfinite(sd)]
    return dict(
        windows=n,
        shares={str(s): int(c) / n for s, c in counts.items()} if n else {},
        sd_km_median=float(np.median(sd)) if len(sd) else None,
        sd_km_p95=float(np.percentile(sd, 95)) if len(sd) else None,
    )


def label_stats(labels: pd.DataFrame) -> dict[str, Any]:
    """The shares of the TOAs labelled to a beacon and called clutter (`beacon_id` empty)."""
    if not len(labels):
        return dict(labelled_share=None, clutter_share=None)
    labelled = float(labels["beacon_id"].notna().mean())
    return dict(labelled_share=labelled, clutter_share=1.0 - labelled)


def run_values(run: Mapping[str, Any], float_id: str) -> dict[str, Any]:
    """From run.json: sound speed and TOA sd used (calibrated or configured), the calibration's
    residual RMS, the clock's drift, the warnings by kind, the contradicted table values."""
    calibration = _mapping(run.get("calibration"))
    fitted = _mapping(calibration.get("values"))
    model = _mapping(_mapping(run.get("config")).get("model"))
    speed, speed_fitted = _used(fitted, model, "sound_speed_m_s")
    sigma, sigma_fitted = _used(fitted, model, "toa_sigma_s")
    warnings = run.get("warnings")
    warnings = warnings if isinstance(warnings, list) else []
    kinds: dict[str, int] = {}
    for message in warnings:
        kind = warning_kind(str(message))
        kinds[kind] = kinds.get(kind, 0) + 1
    contradicted = [c for c in parse_checks(run, float_id) if c.outcome == CONTRADICTED]
    return dict(
        sound_speed_m_s=speed,
        sound_speed_calibrated=speed_fitted,
        toa_sigma_s=sigma,
        toa_sigma_calibrated=sigma_fitted,
        toa_residual_rms_s=number(calibration.get("residual_rms_s")),
        clock_drift_s=clock_drift_s(run, float_id),
        warning_kinds=kinds,
        contradicted=tuple(contradiction(c) for c in contradicted),
    )


def _mapping(value: Any) -> Mapping[str, Any]:
    """`value` when it is a mapping (a JSON object), else an empty one."""
    return value if isinstance(value, Mapping) else {}


def _used(fitted: Mapping[str, Any], model: Mapping[str, Any], key: str) -> tuple[float | None, bool | None]:
    """The value the last pass used for `[model] key`: the calibration's, else the configured."""
    value = number(fitted.get(f"[model] {key}"))
    if value is not None:
        return value, True
    value = number(model.get(key))
    return value, (False if value is not None else None)


def clock_drift_s(run: Mapping[str, Any], float_id: str) -> float | None:
    """The float clock's drift over the record, s: the end offset used minus the launch
    offset used (`metadata_checks` of the float's own clock; None when either is missing)."""
    used: dict[str, float] = {}
    entries = run.get("metadata_checks")
    for entry in entries if isinstance(entries, list) else []:
        if isinstance(entry, Mapping) and str(entry.get("id")) == float_id:
            value = number(entry.get("used"))
            if value is not None:
                used[str(entry.get("field"))] = value
    if "clock_offset_start_s" not in used or "clock_offset_end_s" not in used:
        return None
    return used["clock_offset_end_s"] - used["clock_offset_start_s"]


def contradiction(check: Check) -> tuple[str, str]:
    """What a contradicted check names and what it says: ('beacons.csv line 4: offset_s of
    US1-3', 'given 1530.0 s, arrivals 1497.2 s'); a position as latitude, longitude."""
    given, supported = value_texts(check)
    return f"{table_place(check.file, check.line)}: {check.field} of {check.id}", f"given {given}, arrivals {supported}"


def summarise_float(mission: str, float_id: str, output: Path) -> FloatRow:
    """The row of one tracked float, from track.parquet, labels.parquet and run.json in
    `output`; a row saying why when they cannot be read."""
    row = FloatRow(mission, float_id, output=str(output))
    try:
        run = json.loads((output / "run.json").read_text(encoding="utf-8"))
        if not isinstance(run, dict):
            raise ValueError("run.json does not hold an object")
        track = pd.read_parquet(output / "track.parquet", columns=["lat", "lon", "sd_km", "status"])
        labels = pd.read_parquet(output / "labels.parquet", columns=["beacon_id"])
    except (OSError, ValueError, KeyError) as exc:  # pyarrow's errors are OSError / ValueError
        reason = " ".join(str(getattr(exc, "strerror", None) or exc).splitlines())
        return dataclasses.replace(row, unreadable=f"{output}: {reason}")
    beacons = _mapping(_mapping(run.get("inputs")).get("beacons"))
    return dataclasses.replace(
        row,
        **track_stats(track),
        **label_stats(labels),
        **run_values(run, float_id),
        beacons_file=str(beacons.get("path") or ""),
        lat=track["lat"].to_numpy(dtype=float),
        lon=track["lon"].to_numpy(dtype=float),
    )


def judged(rows: Sequence[FloatRow], rules: LookRules) -> list[FloatRow]:
    """The rows with their look and reasons (`LookRules`), needing a look first (module docstring)."""
    out = []
    for row in rows:
        reasons = rules.reasons(row)
        look = FAILED if row.failed else NEEDS_LOOK if reasons else OK
        out.append(dataclasses.replace(row, look=look, reasons=tuple(reasons)))
    return sorted(out, key=lambda r: (LOOK_ORDER[r.look], -len(r.reasons), r.mission, r.float_id))


def build_overview(
    out: Path,
    outcomes: Sequence[FloatOutcome],
    rules: LookRules | None = None,
    findings: Sequence[Finding] | None = None,
) -> Overview:
    """The overview of a batch's floats: the current outputs of each float processed or
    skipped as unchanged, each failed float with its reason; the others counted. `findings`:
    the floats' metadata findings, when the batch has them already (else read here)."""
    rows = []
    not_tracked = 0
    for outcome in outcomes:
        if outcome.status == FAILED:
            rows.append(FloatRow(outcome.mission, outcome.float_id, failed=outcome.reason or "no reason given"))
        elif is_current(outcome):
            rows.append(summarise_float(outcome.mission, outcome.float_id, Path(outcome.output)))
        else:
            not_tracked += 1
    rules = rules or LookRules()
    found = batch_findings(outcomes)[0] if findings is None else findings
    messages = tuple(f.message().removeprefix("mission : ") for f in found)
    return Overview(Path(out), judged(rows, rules), not_tracked, rules, messages)


# ------------------------------------------------------------------- an existing output tree


def tree_outcomes(out: Path) -> list[FloatOutcome]:
    """The floats of an output tree: the rows of its batch-summary.csv when it has one (each
    output looked for at OUT/<mission>/<float_id>, then where the row says), else every
    directory under OUT (OUT itself included; hidden ones not) holding run.json and
    track.parquet, as processed, its mission the path of its parent under OUT."""
    from .report import SUMMARY_NAME

    summary = out / SUMMARY_NAME
    if summary.is_file():
        with open(summary, newline="", encoding="utf-8") as fh:
            return [_summary_outcome(out, row) for row in csv.DictReader(fh)]
    outcomes = []
    for run_json in sorted(out.rglob("run.json")):
        where = run_json.parent
        parts = where.relative_to(out).parts
        if any(p.startswith(".") for p in parts) or not (where / "track.parquet").is_file():
            continue
        mission = PurePath(*parts[:-1]).as_posix() if len(parts) > 1 else ""
        outcomes.append(
            FloatOutcome(mission, _run_float_id(run_json, where.name), PROCESSED, "found", output=str(where))
        )
    return outcomes


def _summary_outcome(out: Path, row: Mapping[str, str]) -> FloatOutcome:
    mission, float_id = row.get("mission") or "", row.get("float_id") or ""
    output = row.get("output") or ""
    here = out / mission / float_id
    if (here / "run.json").is_file() or not output:
        output = str(here)
    return FloatOutcome(mission, float_id, row.get("status") or "", row.get("reason") or "", output=output)


def _run_float_id(run_json: Path, default: str) -> str:
    try:
        run = json.loads(run_json.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return default
    return str(run.get("float_id") or default) if isinstance(run, dict) else default


def summarise_tree(out: Path, rules: LookRules | None = None) -> Overview:
    """The overview of an existing output tree (`tree_outcomes`); an `InputError` when OUT
    does not exist or holds no tracked float (nor a failed one in its batch-summary.csv)."""
    out = Path(out)
    expected = "expected the output root of 'rafostrack batch' or the --out folder of 'rafostrack track'"
    if not out.is_dir():
        raise InputError(f"{out}: {'not a directory' if out.exists() else 'does not exist'}; {expected}")
    overview = build_overview(out, tree_outcomes(out), rules)
    if not overview.rows:
        raise InputError(f"{out}: holds no tracked float (no folder with run.json and track.parquet); {expected}")
    return overview


# ------------------------------------------------------------------------------ the files


def overview_csv(rows: Sequence[FloatRow]) -> str:
    """The text of overview.csv: a header (`OVERVIEW_COLUMNS`) and one row per float, in order."""
    from ..io.writers import csv_text

    return csv_text(OVERVIEW_COLUMNS, (r.row() for r in rows))


def mission_beacons(rows: Sequence[FloatRow]) -> pd.DataFrame | None:
    """`beacon_id, lat, lon` of the beacons.csv files the floats were tracked with (those that
    can still be read), each beacon once; None when there is none."""
    from ..io.csv_mission import read_beacons

    tables = []
    for name in dict.fromkeys(r.beacons_file for r in rows if r.beacons_file):
        try:
            table = read_beacons(Path(name))
        except (InputError, OSError):
            continue
        tables.append(pd.DataFrame({"beacon_id": table.beacon_id.astype(str), "lat": table.lat, "lon": table.lon}))
    if not tables:
        return None
    return pd.concat(tables, ignore_index=True).drop_duplicates(ignore_index=True)


def map_title(overview: Overview) -> str:
    """'3 floats tracked: 1 needs a look' (and the failed ones, not on the map)."""
    tracked = [r for r in overview.rows if r.look != FAILED]
    needs = sum(r.look == NEEDS_LOOK for r in tracked)
    failed = overview.count(FAILED)
    text = f"{len(tracked)} float{'s' if len(tracked) != 1 else ''} tracked: "
    text += f"{needs} need{'s' if needs == 1 else ''} a look"
    return text + (f"; {failed} failed (not drawn)" if failed else "")


def write_overview(overview: Overview, plots: bool = True) -> list[Path]:
    """overview.png (the map), overview.csv and overview.html (the map inline) in the output
    root, each atomically; their paths. Without `plots` (`--no-plots`) no map is drawn and
    an overview.png left by an earlier run is removed (the page says so)."""
    out = overview.out
    png = out / OVERVIEW_PNG
    image = None
    if plots:
        paths = [FloatPath(r.float_id, r.lat, r.lon, r.look) for r in overview.rows if r.look != FAILED and len(r.lat)]
        plot_mission_map(paths, mission_beacons(overview.rows), png, map_title(overview))
        image = png.read_bytes()
    else:
        png.unlink(missing_ok=True)
    atomic.write_text_atomic(out / OVERVIEW_CSV, overview_csv(overview.rows))
    atomic.write_text_atomic(out / OVERVIEW_HTML, overview_html(overview, image))
    return [out / OVERVIEW_HTML, out / OVERVIEW_CSV, *([png] if plots else [])]


# ------------------------------------------------------------------------------- the page

_STYLE = """
body { font: 14px/1.4 system-ui, sans-serif; margin: 1.5em; color: #222; }
img.map { max-width: 100%; border: 1px solid #ccc; }
table.overview { border-collapse: collapse; font-size: 13px; }
table.overview th, table.overview td { border: 1px solid #ddd; padding: 3px 6px; vertical-align: top; }
table.overview th { background: #f0f0f0; cursor: pointer; position: sticky; top: 0; white-space: nowrap; }
table.overview th[data-order=asc]::after { content: " \\25B2"; }
table.overview th[data-order=desc]::after { content: " \\25BC"; }
table.overview td.num { text-align: right; white-space: nowrap; }
tr.failed td { background: #f8d7d7; }
tr.needs td { background: #fdeeee; }
td .configured { color: #888; }
"""

# Click a header: sort the rows by that column (numbers by value, text alphabetically, empty
# cells last), again to reverse. Each cell's sort key is its data-sort attribute, else its text.
_SCRIPT = """
(function () {
  function key(cell) {
    var k = cell.hasAttribute("data-sort") ? cell.getAttribute("data-sort") : cell.textContent.trim();
    var n = Number(k);
    return k === "" ? null : (isFinite(n) ? n : k.toLowerCase());
  }
  var table = document.querySelector("table.overview");
  var heads = table.tHead.rows[0].cells;
  Array.prototype.forEach.call(heads, function (th, col) {
    th.addEventListener("click", function () {
      var asc = th.getAttribute("data-order") !== "asc";
      Array.prototype.forEach.call(heads, function (h) { h.removeAttribute("data-order"); });
      th.setAttribute("data-order", asc ? "asc" : "desc");
      var body = table.tBodies[0];
      var rows = Array.prototype.slice.call(body.rows);
      rows.sort(function (a, b) {
        var x = key(a.cells[col]), y = key(b.cells[col]);
        if (x === null || y === null) { return (x === null) - (y === null); }
        if (typeof x !== typeof y) { x = String(x); y = String(y); }
        return (x < y ? -1 : x > y ? 1 : 0) * (asc ? 1 : -1);
      });
      rows.forEach(function (r) { body.appendChild(r); });
    });
  });
})();
"""

# The table's columns: header, and the cell of a row as (text, sort key, is a number).
_PERCENT = "{:.1%}"


def _esc(value: object) -> str:
    return html.escape(str(value), quote=True)


def _td(text: str, sort: object = None, num: bool = False, inner_html: str | None = None) -> str:
    """A cell: `text` escaped (or `inner_html`, already escaped), its sort key as data-sort."""
    attrs = ' class="num"' if num else ""
    if sort is not None:
        attrs += f' data-sort="{_esc(sort)}"'
    return f"<td{attrs}>{inner_html if inner_html is not None else _esc(text)}</td>"


def _num_td(value: float | int | None, fmt: str = "{:.1f}", configured: bool = False) -> str:
    """A number's cell, empty when unknown; a value kept as configured (not calibrated) greyed."""
    if value is None:
        return _td("", "", num=True)
    text = _esc(fmt.format(value))
    if configured:
        text = f'<span class="configured" title="as configured, not calibrated">{text}</span>'
    return _td("", value, num=True, inner_html=text)


def _float_link(overview: Overview, row: FloatRow) -> str:
    """The float id, linked to its track.png (else its folder) relative to the page."""
    if not row.output:
        return _td(row.float_id)
    target = Path(row.output) / "track.png"
    target = target if target.is_file() else Path(row.output)
    href = quote(Path(os.path.relpath(target, overview.out)).as_posix() + ("/" if target.is_dir() else ""))
    return _td(row.float_id, row.float_id, inner_html=f'<a href="{_esc(href)}">{_esc(row.float_id)}</a>')


_HEADERS = (
    "look", "mission", "float", "why", "windows", "ok", "ambiguous", "recovered", "unsupported",
    "sd median (km)", "sd p95 (km)", "labelled", "clutter", "sound speed (m/s)", "clock drift (s)",
    "TOA sd (s)", "TOA rms (s)", "warnings", "contradicted table values",
)  # fmt: skip


def _row_html(overview: Overview, row: FloatRow) -> str:
    """One table row: the float's cells in `_HEADERS` order."""
    known = row.windows is not None and not row.unreadable
    cells = [
        _td(row.look, LOOK_ORDER[row.look]),
        _td(row.mission),
        _float_link(overview, row),
        _td("; ".join(row.reasons)),
        _num_td(row.windows, "{:d}"),
        *(_num_td(row.shares.get(s, 0.0) if known else None, _PERCENT) for s in STATUSES),
        _num_td(row.sd_km_median),
        _num_td(row.sd_km_p95),
        _num_td(row.labelled_share, _PERCENT),
        _num_td(row.clutter_share, _PERCENT),
        _num_td(row.sound_speed_m_s, "{:.1f}", configured=row.sound_speed_calibrated is False),
        _num_td(row.clock_drift_s, "{:.2f}"),
        _num_td(row.toa_sigma_s, "{:.2f}", configured=row.toa_sigma_calibrated is False),
        _num_td(row.toa_residual_rms_s, "{:.2f}"),
        _td(_warnings_text(row) if known else "", row.n_warnings if known else ""),
        _td(row.contradicted_text(), len(row.contradicted) if known else ""),
    ]
    css = {FAILED: "failed", NEEDS_LOOK: "needs", OK: "ok"}[row.look]
    return f'<tr class="{css}">' + "".join(cells) + "</tr>"


def _warnings_text(row: FloatRow) -> str:
    """'3: metadata 2, gaps 1', or '0'."""
    return f"{row.n_warnings}: {kinds_text(row.warning_kinds)}" if row.n_warnings else "0"


def _counts_text(overview: Overview) -> str:
    """'3 floats: 1 needs a look (of which 1 failed), 2 ok; 1 not tracked (no arrival file).'"""
    n, failed, needs, ok = len(overview.rows), overview.count(FAILED), overview.count(NEEDS_LOOK), overview.count(OK)
    text = f"{n} float{'s' if n != 1 else ''}: {needs + failed} need{'s' if needs + failed == 1 else ''} a look"
    text += f" (of which {failed} failed), {ok} ok" if failed else f", {ok} ok"
    if overview.not_tracked:
        text += f"; {overview.not_tracked} not tracked (no arrival file yet)"
    return text + "."


def overview_html(overview: Overview, png: bytes | None) -> str:
    """The page: counts, the map (the PNG inline), the sortable table, the rules."""
    title = f"Mission overview: {overview.out}"
    image = (
        f'<p><img class="map" alt="{_esc(map_title(overview))}" '
        f'src="data:image/png;base64,{base64.b64encode(png).decode("ascii")}"></p>'
        if png
        else "<p><em>No map: the batch ran with --no-plots.</em></p>"
    )
    head = "".join(f"<th>{_esc(h)}</th>" for h in _HEADERS)
    body = "\n".join(_row_html(overview, r) for r in overview.rows)
    rules = "".join(f"<li>{_esc(rule)}</li>" for rule in overview.rules.describe())
    findings = "".join(f"<li>{_esc(line)}</li>" for line in overview.findings)
    if findings:
        findings = f"<h2>Table values the arrivals contradict</h2>\n<ul>{findings}</ul>"
    stamp = datetime.now(UTC).isoformat(timespec="seconds")
    return f"""<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>{_esc(title)}</title>
<style>{_STYLE}</style>
</head>
<body>
<h1>{_esc(title)}</h1>
<p><strong>{_esc(_counts_text(overview))}</strong> Floats that need a look come first; click a
column's header to sort by it, again to reverse. A float's name opens its track plot; greyed
values are as configured, not calibrated. The same table is in {_esc(OVERVIEW_CSV)}.</p>
{image}
{findings}
<table class="overview">
<thead><tr>{head}</tr></thead>
<tbody>
{body}
</tbody>
</table>
<h2>A float needs a look when</h2>
<ul>{rules}</ul>
<p>Shares of windows by track status (ok, ambiguous, recovered, unsupported); sd: the
posterior's RMS distance from the position (median and 95th percentile over the windows);
labelled and clutter: shares of the float's TOAs; clock drift: the float clock's end offset
minus its launch offset, as tracked; TOA sd: the arrival-time noise the tracker used; TOA
rms: the calibration's residual RMS of the direct arrivals.</p>
<p><small>Written by rafostrack {_esc(__version__)} at {_esc(stamp)}.</small></p>
<script>{_SCRIPT}</script>
</body>
</html>
"""
