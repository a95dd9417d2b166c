"""batch-summary.csv, the batch's one row per float: its name, its columns, its rows read back.

`report.summary_csv` writes it (one `FloatOutcome.row()` per float, columns
`SUMMARY_COLUMNS`) and `run.py` puts it in the output root; `summary_outcomes` reads it
back, for the overview of an existing tree (`rafostrack summary OUT`).
"""

from __future__ import annotations

import csv
from collections.abc import Mapping
from pathlib import Path

from .plan import FloatOutcome

SUMMARY_NAME = "batch-summary.csv"
SUMMARY_COLUMNS = ("mission", "float_id", "status", "reason", "seconds", "warnings", "output")


def summary_outcomes(out: Path) -> list[FloatOutcome] | None:
    """The floats of OUT's batch-summary.csv, one per row (each output looked for at
    OUT/<mission>/<float_id>, then where the row says); None when OUT has none."""
    summary = Path(out) / SUMMARY_NAME
    if not summary.is_file():
        return None
    with open(summary, newline="", encoding="utf-8") as fh:
        return [_summary_outcome(Path(out), row) for row in csv.DictReader(fh)]


def _summary_outcome(out: Path, row: Mapping[str, str]) -> FloatOutcome:
    mission, float_id = row.get("mission") or "", row.get("float_id") or ""
    output = row.get("output") or ""
    here = out / mission / float_id
    if (here / "run.json").is_file() or not output:
        output = str(here)
    return FloatOutcome(mission, float_id, row.get("status") or "", row.get("reason") or "", output=output)
