"""What every paper's experiments share: a parallel map with per-task seeds, mean and
standard error, and the figure / CSV / JSON writers and command line of an experiment.

Each paper's experiments live in a subpackage (`ranked`, ...), one module per figure or
table, each with `run(outdir, *, quick=False, seed=..., workers=...) -> dict` writing its
PNG(s), the CSVs behind them and a JSON summary; `python -m papers` runs
every paper and writes REPORT.md files.
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import math
import multiprocessing
import os
import time
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from rafostrack import plots
from rafostrack.batch.workers import single_threaded_math
from rafostrack.io.atomic import write_text_atomic
from rafostrack.io.writers import write_json

DPI = 110


# Two workers: the figures' budget is stated for a 2-core machine.
DEFAULT_WORKERS = max(1, min(2, os.cpu_count() or 1))


def pmap(fn: Callable[[Any], Any], tasks: Sequence[Any], workers: int = DEFAULT_WORKERS) -> list[Any]:
    """`[fn(t) for t in tasks]`, in `workers` processes when > 1 (order kept). Every task
    carries its own seed, so results do not depend on scheduling. Workers are spawned with
    single-threaded BLAS: two processes each running a multi-threaded BLAS on two cores are
    slower than one."""
    if workers <= 1 or len(tasks) <= 1:
        return [fn(t) for t in tasks]
    with (
        single_threaded_math(),
        ProcessPoolExecutor(
            max_workers=min(workers, len(tasks)), mp_context=multiprocessing.get_context("spawn")
        ) as pool,
    ):
        return list(pool.map(fn, tasks))


def mean_se(values: Iterable[float]) -> tuple[float, float]:
    """Mean and its standard error (sample sd / sqrt(n); NaN se for n < 2)."""
    v = np.asarray(list(values), dtype=float)
    if len(v) == 0:
        return math.nan, math.nan
    se = float(v.std(ddof=1) / np.sqrt(len(v))) if len(v) > 1 else math.nan
    return float(v.mean()), se


def figure(width: float, height: float) -> contextlib.AbstractContextManager[Figure]:
    """A fresh Agg-backed figure of the experiments' size and resolution."""
    return plots.figure(width, height, dpi=DPI)


def save_csv(frame: pd.DataFrame, path: Path) -> Path:
    write_text_atomic(path, frame.to_csv(index=False, float_format="%.6g", lineterminator="\n"))
    return Path(path)


def experiment(full: Any, quick_sizes: Any) -> Callable[[Callable[..., dict[str, Any]]], Callable[..., dict[str, Any]]]:
    """Decorator for an experiment `run(outdir, sz, **options) -> summary`, where `sz` are its
    sizes. It becomes `run(outdir, *, quick=False, sizes=None, **options)`: `sz` is `full`,
    or `quick_sizes` with `quick`, with the fields in `sizes` replaced (tests use tiny
    sizes); the summary gets `quick` and the wall time (`seconds`) and is written as
    `<outdir>/<name>.json`, which the paper's report is built from."""

    def decorate(run: Callable[..., dict[str, Any]]) -> Callable[..., dict[str, Any]]:
        @functools.wraps(run)
        def wrapper(
            outdir: str | Path, *, quick: bool = False, sizes: dict[str, Any] | None = None, **options: Any
        ) -> dict[str, Any]:
            started = time.perf_counter()
            summary = run(Path(outdir), resolve_sizes(quick_sizes if quick else full, sizes), **options)
            summary.update(quick=quick, seconds=round(time.perf_counter() - started, 1))
            return save_summary(summary, Path(outdir))

        return wrapper

    return decorate


def save_summary(summary: dict[str, Any], outdir: Path) -> dict[str, Any]:
    """Write `<name>.json` (the summary REPORT.md is built from) and return the summary."""
    write_json(Path(outdir) / f"{summary['name']}.json", summary)
    return summary


def cli(run: Callable[..., dict[str, Any]], doc: str | None, argv: Sequence[str] | None = None) -> dict[str, Any]:
    """`python -m papers.<paper>.<module> OUTDIR [--quick] [--seed N] [--workers N]`."""
    parser = argparse.ArgumentParser(description=(doc or "").strip().splitlines()[0])
    parser.add_argument("outdir", type=Path)
    parser.add_argument("--quick", action="store_true", help="small sizes (CI)")
    parser.add_argument("--seed", type=int, default=None)
    parser.add_argument("--workers", type=int, default=DEFAULT_WORKERS)
    args = parser.parse_args(argv)
    kwargs: dict[str, Any] = {"quick": args.quick, "workers": args.workers}
    if args.seed is not None:
        kwargs["seed"] = args.seed
    summary = run(args.outdir, **kwargs)
    print(f"{summary['name']}: wrote {', '.join(summary['files'])} to {args.outdir}")
    return summary


def resolve_sizes(default: Any, overrides: dict[str, Any] | None) -> Any:
    return default if not overrides else type(default)(**{**default.__dict__, **overrides})
