"""`run_batch`: the whole run, in order: check the options, discover, lock, clean, plan, run, report.

Guarantees:

- Usage problems (a bad root, no missions, an unreadable `--config`, a bad `--jobs`, an
  unreachable scheduler, OUT locked by another run) raise `InputError` (exit code 2) before
  anything is written in OUT.
- Everything that writes in OUT happens while holding OUT's lock (`lock.py`): first the
  temporary directories and files a killed run left in OUT are removed, then the floats are
  planned and run, then each mission's array (`array_rounds.py`), `batch-summary.csv`,
  `metadata-findings.csv`, the mission overview (`overview.html`, `overview.csv`,
  `overview.png`) are written atomically; `batch.log` is written as the run
  goes, one whole line at a time (`report.Reporter.log_file`).
- The result's exit code is 0 when no float failed, 1 when some did.
"""

from __future__ import annotations

import dataclasses
import os
import re
import shutil
import socket
import sys
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

from .. import __version__
from ..config import load_config
from ..errors import InputError
from ..io.outdir import SIBLING
from .array_rounds import MAX_ROUNDS, calibrated_tables, fit_mission, replaced, round_line
from .discover import Mission, discover
from .findings import findings_csv
from .lock import BatchLock
from .plan import FAILED, SKIPPED, FloatOutcome, FloatTask, plan
from .pool import dask_client, local_workers, ordered_map, run_dask, run_local
from .report import (
    FINDINGS_NAME,
    LOG_NAME,
    SUMMARY_NAME,
    Reporter,
    report_findings,
    report_overview,
    summary_csv,
    summary_table,
)

_STALE_FILE = re.compile(r"^\..+\.tmp$")  # atomic_path's temporary files
# The table earlier versions wrote from the floats' findings alone, removed from OUT: the
# values it held were not the mission's (the array fit's `beacons-calibrated.csv` is).
LEGACY_SUPPORTED_NAME = "beacons-supported.csv"


def default_jobs() -> int:
    """The cores this process may use (its CPU affinity where known, else all)."""
    try:
        return len(os.sched_getaffinity(0)) or 1
    except AttributeError:
        return os.cpu_count() or 1


@dataclass
class BatchResult:
    outcomes: list[FloatOutcome]
    exit_code: int  # 0 all good, 1 some floats failed
    summary: str  # the table to print

    def count(self, status: str) -> int:
        return sum(o.status == status for o in self.outcomes)


@dataclass(frozen=True)
class BatchOptions:
    roots: tuple[Path, ...]
    out: Path
    jobs: int
    force: bool
    scheduler: str | None
    config_files: tuple[Path, ...]
    overrides: dict[str, dict[str, Any]]
    plots: bool
    array_fit: bool = True


def run_batch(
    roots: Sequence[Path],
    out: Path,
    *,
    jobs: int | None = None,
    force: bool = False,
    scheduler: str | None = None,
    config_file: Path | None = None,
    overrides: dict[str, dict[str, Any]] | None = None,
    plots: bool = True,
    array_fit: bool = True,
    stream: TextIO | None = None,
    tty: bool | None = None,
) -> BatchResult:
    """Discover, plan, run and report (see the package docstring). Usage problems (a bad root,
    no missions, a bad --config, an unreachable scheduler, OUT locked by another run) raise
    `InputError` before anything is written."""
    stream = stream if stream is not None else sys.stderr
    tty = tty if tty is not None else bool(getattr(stream, "isatty", lambda: False)())
    jobs = jobs if jobs is not None else default_jobs()
    if jobs < 1:
        raise InputError(f"--jobs must be >= 1, got {jobs}")
    options = BatchOptions(
        roots=tuple(Path(r) for r in roots),
        out=Path(out),
        jobs=jobs,
        force=force,
        scheduler=scheduler,
        config_files=(Path(config_file).resolve(),) if config_file is not None else (),
        overrides=overrides or {},
        plots=plots,
        array_fit=array_fit,
    )
    load_config(options.config_files, options.overrides)  # a bad --config or flag: exit 2
    missions = discover(options.roots, exclude=options.out)
    if not missions:
        raise InputError(
            f"no mission directories under {', '.join(map(str, roots))} "
            "(a mission directory holds beacons.csv, floats.csv and <float_id>.csv files)"
        )
    client = dask_client(scheduler) if scheduler else None
    try:
        options.out.mkdir(parents=True, exist_ok=True)
        reporter = Reporter(stream, tty)
        with BatchLock(options.out, reporter.log) as lock, reporter.log_file(options.out / LOG_NAME):
            outcomes, table = _run_locked(options, missions, lock, reporter, client)
    finally:
        if client is not None:
            client.close()
    exit_code = 1 if any(o.status == FAILED for o in outcomes) else 0
    return BatchResult(outcomes, exit_code, table)


def _run_locked(
    options: BatchOptions, missions: list[Mission], lock: BatchLock, reporter: Reporter, client: Any
) -> tuple[list[FloatOutcome], str]:
    """Everything done while holding OUT's lock: clean, plan, run, write the reports."""
    started = time.monotonic()
    out = options.out
    reporter.log(
        f"rafostrack {__version__}, pid {os.getpid()} on {socket.gethostname()}; "
        f"roots: {' '.join(map(str, options.roots))}; out: {out}",
        console=False,
    )
    clean_stale(out, missions, reporter.log)
    tables = calibrated_tables(missions, out) if options.array_fit else {}
    tasks, known = _plan_floats(options, missions, lock, reporter, client, tables)
    outcomes = known + _track(tasks, options, reporter, client)
    if options.array_fit:
        outcomes = _array_rounds(options, missions, lock, reporter, client, outcomes)
    outcomes.sort(key=lambda o: (o.mission, o.float_id))
    return outcomes, _write_reports(options, missions, reporter, outcomes, started)


def _track(tasks: list[FloatTask], options: BatchOptions, reporter: Reporter, client: Any) -> list[FloatOutcome]:
    """Run the tasks (local worker processes or Dask), each outcome reported as it comes."""
    outcomes = []
    reporter.start(len(tasks))
    try:
        if client is not None:
            runner = run_dask(tasks, client)
        else:
            runner = run_local(
                tasks, options.jobs, on_stderr=lambda text: _log_worker_stderr(reporter, text, options.out)
            )
        for outcome in runner:
            outcomes.append(outcome)
            reporter.done(outcome)
    finally:
        reporter.finish()
    return outcomes


def _array_rounds(
    options: BatchOptions,
    missions: list[Mission],
    lock: BatchLock,
    reporter: Reporter,
    client: Any,
    outcomes: list[FloatOutcome],
) -> list[FloatOutcome]:
    """Fit each mission's array and track its floats again with it, until the tables settle
    (`array_rounds`); the outcomes with each retracked float's latest."""
    for round_ in range(1, MAX_ROUNDS + 1):
        fitted, tables = [], {}
        with ordered_map(options.jobs, client) as map_floats:
            for mission in missions:
                result = fit_mission(
                    mission, options.out, options.config_files, options.overrides, options.plots, round_, map_floats
                )
                if result is None:
                    continue
                reporter.log(round_line(result, round_))
                fitted.append(mission)
                if result.calibrated is not None:
                    tables[mission.name] = result.calibrated
        if round_ == MAX_ROUNDS or not fitted:
            break
        tasks, _ = _planned(options, fitted, lock, tables, force=False)
        if not tasks:
            break
        reporter.log(f"round {round_ + 1}: tracking {len(tasks)} float(s) again with their mission's array")
        why = f"round {round_ + 1}: tracked with the mission's array"
        tasks = [dataclasses.replace(task, why=why) for task in tasks]
        outcomes = replaced(outcomes, _track(tasks, options, reporter, client))
    return outcomes


def _planned(
    options: BatchOptions, missions: list[Mission], lock: BatchLock, tables: dict[str, Path], force: bool
) -> tuple[list[FloatTask], list[FloatOutcome]]:
    """`plan` of the missions' floats with the run's options, each mission's floats tracked
    with its table in `tables` (else its beacons.csv)."""
    return plan(
        missions,
        options.out,
        config_files=options.config_files,
        overrides=options.overrides,
        plots=options.plots,
        force=force,
        run_id=lock.run_id,
        beacons_of=tables,
    )


def _plan_floats(
    options: BatchOptions,
    missions: list[Mission],
    lock: BatchLock,
    reporter: Reporter,
    client: Any,
    tables: dict[str, Path],
) -> tuple[list[FloatTask], list[FloatOutcome]]:
    """The floats to run and those known without running (skipped, or failed before
    running), each logged; `tables`: the calibrated table a mission's floats are tracked with."""
    for mission in missions:
        if mission.orphans:
            names = ", ".join(f"{f}.csv" for f in mission.orphans)
            reporter.log(f"{mission.name}: ignoring {names} (no row in floats.csv)", console=False)
    tasks, known = _planned(options, missions, lock, tables, force=options.force)
    skipped = sum(o.status == SKIPPED for o in known)
    if not tasks:  # nothing to run: no worker starts
        where = ""
    elif client is not None:
        where = f" on Dask scheduler {options.scheduler}"
    else:
        where = f" with {local_workers(options.jobs, len(tasks))} local worker process(es)"
    reporter.log(
        f"{len(tasks) + len(known)} floats in {len(missions)} mission(s): {len(tasks)} to process{where}, "
        f"{skipped} skipped, {len(known) - skipped} failed before running"
    )
    for outcome in known:
        line = f"{outcome.mission}/{outcome.float_id} {outcome.status}: {outcome.reason}"
        reporter.log(line, console=outcome.status == FAILED)
    return tasks, known


def _write_reports(
    options: BatchOptions, missions: list[Mission], reporter: Reporter, outcomes: list[FloatOutcome], started: float
) -> str:
    """The run's reports in OUT (the summary, the findings, the overview, in this order;
    batch.log's last lines); returns the summary table to print (the run's seconds counted
    from `started`, a `time.monotonic()`)."""
    from ..io.atomic import write_text_atomic

    out = options.out
    findings = report_findings(reporter, outcomes, out)
    table = summary_table(outcomes, time.monotonic() - started, out)
    reporter.lines.extend(table.splitlines())
    write_text_atomic(out / SUMMARY_NAME, summary_csv(outcomes))
    write_text_atomic(out / FINDINGS_NAME, findings_csv(findings))
    for mission in missions:  # the array fit writes the mission's table (beacons-calibrated.csv)
        (out / mission.name / LEGACY_SUPPORTED_NAME).unlink(missing_ok=True)
        if not options.array_fit:
            _remove_array_outputs(out / mission.name, reporter)
    report_overview(reporter, outcomes, out, findings, plots=options.plots)
    return table


def _remove_array_outputs(folder: Path, reporter: Reporter) -> None:
    """An earlier run's array fit of the mission, removed from `folder` (with a log line):
    under --no-array-fit its floats are tracked with the tables as given, and the overview
    would show a fit their tracks no longer rest on."""
    from ..mission.outputs import ARRAY_NAME, ARRAY_PLOT_NAME, CALIBRATED_NAME
    from .array_rounds import ARRAY_JSON

    found = [folder / name for name in (ARRAY_NAME, ARRAY_JSON, ARRAY_PLOT_NAME, CALIBRATED_NAME)]
    found = [path for path in found if path.is_file()]
    for path in found:
        path.unlink()
    if found:
        names = ", ".join(path.name for path in found)
        reporter.log(f"{folder}: an earlier run's array fit removed ({names}): --no-array-fit uses the tables as given")


def _log_worker_stderr(reporter: Reporter, text: str, out: Path) -> None:
    """What the local workers wrote on stderr goes to batch.log, with a line saying so."""
    lines = text.rstrip("\n").splitlines()
    reporter.log(f"the local worker processes wrote {len(lines)} line(s) on stderr, kept in {Path(out) / LOG_NAME}")
    reporter.lines.extend(f"  worker stderr: {line}" for line in lines)


def clean_stale(out: Path, missions: Iterable[Mission], log: Callable[[str], None]) -> None:
    """Remove temporary directories and files that a killed run left in OUT (under the lock,
    so no other batch run is writing there)."""
    places = [Path(out)] + [Path(out) / m.name for m in missions]
    for place in dict.fromkeys(places):
        try:
            entries = list(os.scandir(place))
        except OSError:
            continue
        for entry in entries:
            if entry.is_dir(follow_symlinks=False) and SIBLING.match(entry.name):
                shutil.rmtree(entry.path, ignore_errors=True)
                log(f"removed {entry.path} (left by an interrupted run)")
            elif entry.is_file(follow_symlinks=False) and _STALE_FILE.match(entry.name):
                Path(entry.path).unlink(missing_ok=True)
                log(f"removed {entry.path} (left by an interrupted run)")
