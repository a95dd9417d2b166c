"""Run a paper's experiments (or read their summaries) and build its report; run every paper.

A paper's package (`rafostrack.experiments.<paper>`) has one module per figure or table,
each with `run(outdir, *, quick, workers) -> dict` writing `<name>.json`, and a `report`
module with `EXPERIMENTS` (the module names, in report order), `TITLE` and
`build_report(outdir, summaries=None, total_s=None) -> Path` (REPORT.md from the JSON
summaries only, so it can be rebuilt without rerunning anything).

    python -m rafostrack.experiments [--quick] [--out figures] [--papers ranked ...]
    python -m rafostrack.experiments.<paper> [--quick] [--out DIR] [--only NAME ...] [--report-only]
"""

from __future__ import annotations

import argparse
import importlib
import json
import time
from collections.abc import Sequence
from pathlib import Path
from types import ModuleType
from typing import Any

from ..io.atomic import write_text_atomic
from .common import DEFAULT_WORKERS

# Every paper whose experiments `make figures` redoes, in the order of the index.
PAPERS = ("ranked", "context", "abc", "legs")


def report_module(paper: str) -> ModuleType:
    return importlib.import_module(f"rafostrack.experiments.{paper}.report")


def run_experiments(
    paper: str, outdir: Path, *, quick: bool, workers: int, only: Sequence[str] | None = None
) -> dict[str, dict[str, Any]]:
    """Run a paper's experiments in `only` (default: all), each with its default seed."""
    summaries = {}
    for name in only or report_module(paper).EXPERIMENTS:
        module = importlib.import_module(f"rafostrack.experiments.{paper}.{name}")
        started = time.perf_counter()
        summaries[name] = module.run(Path(outdir), quick=quick, workers=workers)
        print(f"{paper}.{name}: {time.perf_counter() - started:.1f} s", flush=True)
    return summaries


def read_summaries(outdir: Path, names: Sequence[str]) -> dict[str, dict[str, Any]]:
    """The `<name>.json` summaries present in `outdir`, in the order of `names`."""
    out = {}
    for name in names:
        path = Path(outdir) / f"{name}.json"
        if path.is_file():
            out[name] = json.loads(path.read_text(encoding="utf-8"))
    return out


def run_paper(paper: str, outdir: Path, *, quick: bool, workers: int, only: Sequence[str] | None = None) -> Path:
    """Run a paper's experiments into `outdir` and write its REPORT.md there."""
    report = report_module(paper)
    started = time.perf_counter()
    run_experiments(paper, outdir, quick=quick, workers=workers, only=only)
    complete = only is None or set(only) == set(report.EXPERIMENTS)
    return report.build_report(outdir, total_s=time.perf_counter() - started if complete else None)


def paper_main(paper: str, argv: Sequence[str] | None = None) -> None:
    """`python -m rafostrack.experiments.<paper>`."""
    report = report_module(paper)
    parser = argparse.ArgumentParser(
        prog=f"python -m rafostrack.experiments.{paper}", description=f"Redo {report.TITLE}; write REPORT.md."
    )
    parser.add_argument("--out", type=Path, default=Path("figures") / paper, help=f"output directory (figures/{paper})")
    parser.add_argument("--quick", action="store_true", help="small sizes (CI)")
    parser.add_argument("--workers", type=int, default=DEFAULT_WORKERS, help="worker processes (default 2)")
    parser.add_argument("--only", nargs="+", choices=report.EXPERIMENTS, default=None)
    parser.add_argument("--report-only", action="store_true", help="rebuild REPORT.md from the JSON summaries")
    args = parser.parse_args(argv)
    started = time.perf_counter()
    if args.report_only:
        path = report.build_report(args.out)
    else:
        path = run_paper(paper, args.out, quick=args.quick, workers=args.workers, only=args.only)
    print(f"wrote {path} ({time.perf_counter() - started:.1f} s)")


def main(argv: Sequence[str] | None = None) -> None:
    """`python -m rafostrack.experiments`: every paper into `<out>/<paper>/`, and an index."""
    parser = argparse.ArgumentParser(
        prog="python -m rafostrack.experiments", description="Redo every paper's experiments; write the reports."
    )
    parser.add_argument("--out", type=Path, default=Path("figures"), help="output directory (default figures/)")
    parser.add_argument("--quick", action="store_true", help="small sizes (CI)")
    parser.add_argument("--workers", type=int, default=DEFAULT_WORKERS, help="worker processes (default 2)")
    parser.add_argument("--papers", nargs="+", choices=PAPERS, default=list(PAPERS))
    args = parser.parse_args(argv)
    started = time.perf_counter()
    rows = []
    for paper in args.papers:
        t0 = time.perf_counter()
        path = run_paper(paper, args.out / paper, quick=args.quick, workers=args.workers)
        rows.append(f"| [{report_module(paper).TITLE}]({paper}/{path.name}) | {time.perf_counter() - t0:.0f} |")
    lines = [
        "# rafostrack: the papers' experiments, redone",
        "",
        "Generated by `python -m rafostrack.experiments"
        + (" --quick" if args.quick else "")
        + "`"
        + (" (**quick mode: small sizes; numbers are indicative only**)" if args.quick else "")
        + ".",
        "",
        "| paper | seconds |",
        "|---|---:|",
        *rows,
        "",
    ]
    index = args.out / "REPORT.md"
    write_text_atomic(index, "\n".join(lines))
    print(f"wrote {index} ({time.perf_counter() - started:.1f} s)")
