"""What a batch run tells: progress, the summary table, `batch-summary.csv`, `batch.log`, and
the metadata findings (`metadata-findings.csv`).

Guarantees:

- On a terminal, a progress bar (`tqdm`) with the counts processed and failed; failures and
  other messages are printed above it. Otherwise (cron, a pipe) no bar and no carriage
  returns: one plain line per float, `rafostrack batch: [n/total] <mission>/<float> ...`.
- Every message, every float's line and the traceback of any unexpected error go to
  `batch.log`, each line time-stamped (UTC), as they come: once the run holds OUT's lock
  the file is emptied, given the lines so far, and each line after is appended with one
  `os.write` on an `O_APPEND` file (no buffer to flush), so a killed run leaves whole lines,
  one per float it finished (`Reporter.log_file`).
- The summary table lists every float processed or failed, with its reason, and the totals
  (skipped floats are counted; all floats are listed in `batch-summary.csv`, one row each,
  columns `SUMMARY_COLUMNS`: `summary_file.py`), which `run.py` writes atomically at the end of the run.
- The metadata findings (`findings.py`): one line per table value the arrivals contradict,
  printed at the end, and `metadata-findings.csv` (columns `FINDINGS_COLUMNS`; a header
  only when there is none), which `run.py` writes atomically beside `batch-summary.csv`.
- The mission overview (`overview.py`): `overview.html`, `overview.csv` and `overview.png`
  written atomically in OUT, and one line naming the floats that need a look. A failure to
  write it is logged (with its traceback in batch.log) and does not fail the batch.
"""

from __future__ import annotations

import contextlib
import os
import time
import traceback
from collections.abc import Iterable, Iterator, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import TextIO

from tqdm import tqdm

from ..io.writers import csv_text
from .findings import FINDINGS_NAME, Finding, batch_findings
from .overview import OK, OVERVIEW_HTML, build_overview, write_overview
from .plan import FAILED, PROCESSED, SKIPPED, FloatOutcome
from .summary_file import SUMMARY_COLUMNS, SUMMARY_NAME

LOG_NAME = "batch.log"

_BAR_FORMAT = "{percentage:3.0f}%|{bar}| {n_fmt}/{total_fmt} floats [{elapsed}<{remaining}{postfix}]"


class LogLines(list[str]):
    """batch.log's lines, in order; while a log file is open (`fd`), each line appended is
    written to it at once, whole, with one `os.write` (the file is `O_APPEND`)."""

    fd: int | None = None

    def append(self, line: str, /) -> None:
        super().append(line)
        if self.fd is not None:
            os.write(self.fd, f"{line}\n".encode())

    def extend(self, lines: Iterable[str], /) -> None:
        for line in lines:
            self.append(line)


class Reporter:
    """Progress and log lines. On a terminal: a progress bar with log lines above it;
    otherwise (cron) one plain line per event. Every line also goes to `lines` (batch.log)."""

    def __init__(self, stream: TextIO, tty: bool):
        self.stream = stream
        self.tty = tty
        self.lines = LogLines()
        self.total = 0
        self.counts = {PROCESSED: 0, FAILED: 0}
        self.started = time.monotonic()
        self._bar: tqdm | None = None

    @contextlib.contextmanager
    def log_file(self, path: Path) -> Iterator[None]:
        """Write `lines` to `path` (batch.log) as they come: the file emptied, the lines so far
        written, then each new line appended (`LogLines`); closed on leaving."""
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_APPEND, 0o644)
        try:
            if self.lines:
                os.write(fd, "".join(f"{line}\n" for line in self.lines).encode())
            self.lines.fd = fd
            yield
        finally:
            self.lines.fd = None
            os.close(fd)

    def log(self, message: str, console: bool = True) -> None:
        stamp = datetime.now(UTC).isoformat(timespec="seconds")
        self.lines.append(f"{stamp} {message}")
        if not console:
            return
        text = f"rafostrack batch: {message}"
        if self._bar is not None:
            self._bar.write(text, file=self.stream)  # clears the bar, writes the line, redraws the bar
        else:
            self.stream.write(text + "\n")
        self.stream.flush()

    def start(self, total: int) -> None:
        """Count `total` floats from 0 (each round of a batch counts its own)."""
        self.total = total
        self.counts = {PROCESSED: 0, FAILED: 0}
        self.started = time.monotonic()
        if self.tty and total:
            self._bar = tqdm(
                total=total,
                file=self.stream,
                bar_format=_BAR_FORMAT,
                dynamic_ncols=True,
                leave=False,
                mininterval=0.2,
            )
            self._bar.set_postfix_str(self._counts_text(), refresh=True)

    def done(self, outcome: FloatOutcome) -> None:
        self.counts[outcome.status] = self.counts.get(outcome.status, 0) + 1
        n = sum(self.counts.values())
        where = f"{outcome.mission}/{outcome.float_id}"
        if outcome.status == PROCESSED:
            took = f" in {outcome.seconds:.1f} s" if outcome.seconds is not None else ""
            warn = f", {outcome.warnings} input warning(s)" if outcome.warnings else ""
            message = f"[{n}/{self.total}] {where} processed{took} ({outcome.reason}{warn})"
        else:
            message = f"[{n}/{self.total}] {where} {outcome.status}: {outcome.reason}"
        # On a terminal only failures interrupt the bar; under cron every float gets a line.
        self.log(message, console=not self.tty or outcome.status == FAILED)
        if outcome.detail:
            self.lines.append(outcome.detail.rstrip())
        if self._bar is not None:
            self._bar.set_postfix_str(self._counts_text(), refresh=False)
            self._bar.update(1)

    def finish(self) -> None:
        if self._bar is not None:
            self._bar.close()  # leave=False: the bar is erased; the summary table follows
            self._bar = None
        self.stream.flush()

    def _counts_text(self) -> str:
        return f"processed {self.counts[PROCESSED]}, failed {self.counts[FAILED]}"


def summary_table(outcomes: Sequence[FloatOutcome], elapsed_s: float, out: Path) -> str:
    """The table printed at the end: every float processed or failed (skipped ones are
    counted; all are listed in batch-summary.csv), then the totals."""
    counts = {s: sum(o.status == s for o in outcomes) for s in (PROCESSED, SKIPPED, FAILED)}
    shown = [o for o in outcomes if o.status != SKIPPED or o.reason != "unchanged"]
    lines = []
    if shown:
        header = ("mission", "float_id", "status", "seconds", "reason")
        rows = [(o.mission, o.float_id, o.status, o.row()["seconds"], o.reason) for o in shown]
        widths = [max(len(str(r[i])) for r in [header, *rows]) for i in range(4)]
        for r in [header, *rows]:
            lines.append("  ".join(str(r[i]).ljust(widths[i]) for i in range(4)) + "  " + str(r[4]))
    unchanged = len(outcomes) - len(shown)
    lines.append(
        f"{len(outcomes)} floats: {counts[PROCESSED]} processed, {counts[SKIPPED]} skipped"
        f"{f' ({unchanged} unchanged)' if unchanged else ''}, {counts[FAILED]} failed in {elapsed_s:.1f} s"
    )
    lines.append(
        f"summary: {Path(out) / SUMMARY_NAME}  log: {Path(out) / LOG_NAME}  findings: {Path(out) / FINDINGS_NAME}"
        f"  overview: {Path(out) / OVERVIEW_HTML}"
    )
    return "\n".join(lines)


def summary_csv(outcomes: Sequence[FloatOutcome]) -> str:
    """The text of batch-summary.csv: a header and one row per float."""
    return csv_text(SUMMARY_COLUMNS, (outcome.row() for outcome in outcomes))


def report_findings(reporter: Reporter, outcomes: Sequence[FloatOutcome], out: Path) -> list[Finding]:
    """Print the metadata findings of the floats' run.json files, one line each (stderr and
    batch.log), and return them (`findings_csv` is the text of metadata-findings.csv)."""
    findings, unreadable = batch_findings(outcomes)
    for line in unreadable:
        reporter.log(line)
    path = Path(out) / FINDINGS_NAME
    if not findings:
        reporter.log(f"metadata findings: no table value contradicted by the arrivals ({path})", console=False)
    else:
        reporter.log(f"metadata findings: {len(findings)} table value(s) contradicted by the arrivals ({path}):")
    for finding in findings:
        reporter.log(finding.message())
    return findings


_SHOWN_NEEDING = 5  # float names printed in the overview's line (all are in overview.html)


def report_overview(
    reporter: Reporter,
    outcomes: Sequence[FloatOutcome],
    out: Path,
    findings: Sequence[Finding],
    plots: bool = True,
) -> None:
    """Write the mission overview of the batch's floats and their metadata `findings` in OUT
    (`overview.write_overview`; the map only with `plots`) and log one line naming the
    floats that need a look (on the console when there are any)."""
    try:
        overview = build_overview(Path(out), outcomes, findings=findings)
        write_overview(overview, plots=plots, notice=lambda message: reporter.log(f"overview: {message}"))
    except Exception as exc:  # the floats are done; a broken overview must not hide their summary
        reporter.log(f"overview: cannot be written: {type(exc).__name__}: {' '.join(str(exc).splitlines())}")
        reporter.lines.append(traceback.format_exc().rstrip())
        return
    needing = [r for r in overview.rows if r.look != OK]
    path = Path(out) / OVERVIEW_HTML
    if not needing:
        reporter.log(f"overview: no float needs a look ({path})", console=False)
        return
    names = ", ".join(f"{r.mission}/{r.float_id}" if r.mission else r.float_id for r in needing[:_SHOWN_NEEDING])
    more = ", ..." if len(needing) > _SHOWN_NEEDING else ""
    reporter.log(f"overview: {len(needing)} of {len(overview.rows)} floats need a look ({names}{more}): {path}")
