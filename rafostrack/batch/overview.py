"""The mission overview: which floats of an output tree need a look, in one table and one map.

Written in the output root at the end of every `rafostrack batch` (`run.py`), and by
`rafostrack summary OUT` for an existing tree (a batch output root, or a `rafostrack track
--out` folder): `overview.csv` (one row per float, columns `OVERVIEW_COLUMNS`),
`overview.png` (every track on one map, `plots.mission_map`) and `overview.html` (the map
inline and the table, sorted by a click on a column's header), each written atomically.

One module per concept:

- `overview_rows.py`: one float's row, from its outputs (track.parquet, labels.parquet,
  run.json; the warnings counted by the kind each was made with, run.json's
  `warning_kinds`), and the text of overview.csv;
- `triage.py`: when a float needs a look (`LookRules`) and the order shown (`judged`);
- `overview_array.py`: each mission's array fit (array.csv, array.json), its section of the page;
- `overview_page.py`: overview.html;
- here: the overview of a batch's floats or of an existing tree, and its three files.

A float that failed in the batch is listed with its reason; a float not tracked (no arrival
file yet) is only counted.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from pathlib import Path, PurePath

import pandas as pd

from ..errors import InputError
from ..io import atomic
from ..io.csv_mission import read_beacons
from ..plots.mission_map import OK, FloatPath, plot_mission_map
from .findings import Finding, batch_findings, is_current
from .overview_array import mission_arrays
from .overview_page import OVERVIEW_HTML, map_title, overview_html
from .overview_rows import OVERVIEW_COLUMNS, OVERVIEW_CSV, FloatRow, overview_csv, summarise_float
from .plan import FAILED, PROCESSED, FloatOutcome
from .summary_file import summary_outcomes
from .triage import LookRules, Overview, judged

__all__ = [
    "OK",
    "OVERVIEW_COLUMNS",
    "OVERVIEW_CSV",
    "OVERVIEW_HTML",
    "OVERVIEW_PNG",
    "FloatRow",
    "LookRules",
    "Overview",
    "build_overview",
    "summarise_tree",
    "tree_outcomes",
    "write_overview",
]

OVERVIEW_PNG = "overview.png"


def build_overview(
    out: Path,
    outcomes: Sequence[FloatOutcome],
    rules: LookRules | None = None,
    findings: Sequence[Finding] | None = None,
) -> Overview:
    """The overview of a batch's floats: the current outputs of each float processed or
    skipped as unchanged, each failed float with its reason; the others counted; each
    mission's array fit (OUT/<mission>/array.csv, when there is one). `findings`: the
    floats' metadata findings, when the batch has them already (else read here)."""
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
    arrays = mission_arrays(Path(out), (r.mission for r in rows))
    return Overview(Path(out), judged(rows, rules), not_tracked, rules, messages, arrays)


# ------------------------------------------------------------------- an existing output tree


def tree_outcomes(out: Path) -> list[FloatOutcome]:
    """The floats of an output tree: the rows of its batch-summary.csv when it has one (each
    output looked for at OUT/<mission>/<float_id>, then where the row says), else every
    directory under OUT (OUT itself included; hidden ones not) holding run.json and
    track.parquet, as processed, its mission the path of its parent under OUT."""
    listed = summary_outcomes(out)
    if listed is not None:
        return listed
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


def mission_beacons(rows: Sequence[FloatRow]) -> tuple[pd.DataFrame | None, list[str]]:
    """`beacon_id, lat, lon` of the beacons.csv files the floats were tracked with (those that
    can still be read), each beacon once (None when there is none); and the files that
    cannot be read."""
    tables, unread = [], []
    for name in dict.fromkeys(r.beacons_file for r in rows if r.beacons_file):
        try:
            table = read_beacons(Path(name))
        except (InputError, OSError):
            unread.append(name)
            continue
        tables.append(pd.DataFrame({"beacon_id": table.beacon_id.astype(str), "lat": table.lat, "lon": table.lon}))
    if not tables:
        return None, unread
    return pd.concat(tables, ignore_index=True).drop_duplicates(ignore_index=True), unread


def write_overview(overview: Overview, plots: bool = True, notice: Callable[[str], None] | None = None) -> list[Path]:
    """overview.png (the map), overview.csv and overview.html (the map inline) in the output
    root, each atomically; their paths. Without `plots` (`--no-plots`) no map is drawn and
    an overview.png left by an earlier run is removed (the page says so). `notice` is told,
    in one line, of the beacon tables the map cannot draw (not found or not readable)."""
    out = overview.out
    png = out / OVERVIEW_PNG
    image = None
    if plots:
        paths = [FloatPath(r.float_id, r.lat, r.lon, r.look) for r in overview.rows if r.look != FAILED and len(r.lat)]
        beacons, unread = mission_beacons(overview.rows)
        if unread and notice is not None:
            notice(f"{png.name}: beacons not drawn: {', '.join(unread)} (run.json's beacon table) cannot be read")
        plot_mission_map(paths, beacons, png, map_title(overview))
        image = png.read_bytes()
    else:
        png.unlink(missing_ok=True)
    atomic.write_text_atomic(out / OVERVIEW_CSV, overview_csv(overview.rows))
    atomic.write_text_atomic(out / OVERVIEW_HTML, overview_html(overview, image))
    return [out / OVERVIEW_HTML, out / OVERVIEW_CSV, *([png] if plots else [])]
