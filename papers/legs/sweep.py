"""One factor varied, the others at the paper's defaults (Figs. 5-7): paired repeats.

For each level of the factor, R repeats; a repeat simulates one target and its
measurements (its own seed) and runs every method on them, so methods are compared on
the same data. Reported per level and method: the mean SS error per time step over the
repeats, its standard error and median; and per level the paired difference of each RW
variant minus the Kalman filter with its standard error and the repeats it wins.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from rafostrack.plots import save_png

from ..common import DEFAULT_WORKERS, figure, mean_se, pmap, save_csv
from .methods import LABELS, run_methods
from .target import Scenario, make_run

STYLE = {
    "rw_paper": ("tab:blue", "^"),
    "rw_paper_var": ("tab:cyan", "v"),
    "rw_ours": ("tab:green", "o"),
    "rw_student": ("tab:olive", "D"),
    "kf": ("tab:red", "s"),
    "ks": ("tab:orange", "x"),
}


DEFAULTS = Scenario()  # the paper's default settings


@dataclass(frozen=True)
class Sizes:
    repeats: int
    iterations: int


def _task(task: tuple[Scenario, str, int, Any, int, int, int, tuple[str, ...]]) -> list[dict[str, Any]]:
    base, factor, level_index, level, rep, seed, iterations, methods = task
    scenario = dataclasses.replace(base, **{factor: level})
    run = make_run(scenario, np.random.default_rng([seed, level_index, rep]))
    rows = run_methods(run, iterations, [seed, level_index, rep, 1], methods)
    return [{"level": level, "repeat": rep, **row} for row in rows]


def run_sweep(
    factor: str, levels: tuple[Any, ...], methods: tuple[str, ...], sz: Sizes, seed: int,
    workers: int = DEFAULT_WORKERS, base: Scenario = DEFAULTS,
) -> pd.DataFrame:  # fmt: skip
    """Every method on R repeats at every level; one row per (level, repeat, method)."""
    tasks = [
        (base, factor, i, lv, rep, seed, sz.iterations, methods)
        for i, lv in enumerate(levels)
        for rep in range(sz.repeats)
    ]
    return pd.DataFrame([row for rows in pmap(_task, tasks, workers) for row in rows])


def aggregate(raw: pd.DataFrame, levels: tuple[Any, ...], methods: tuple[str, ...]) -> list[dict[str, Any]]:
    """Per level: mean, se and median SS / time of each method; paired RW - KF differences."""
    table = []
    for level in levels:
        g = raw[raw["level"] == level]
        row: dict[str, Any] = {"level": level}
        for m in methods:
            v = g.loc[g["method"] == m, "ss_per_time"]
            row[f"{m}_mean"], row[f"{m}_se"] = mean_se(v)
            row[f"{m}_median"] = float(v.median())
            row[f"{m}_seconds"] = float(g.loc[g["method"] == m, "seconds"].mean())
        wide = g.pivot_table(index="repeat", columns="method", values="ss_per_time")
        for m in methods:
            if m.startswith("rw") and "kf" in wide:
                diff = wide[m] - wide["kf"]
                row[f"{m}_minus_kf"], row[f"{m}_minus_kf_se"] = mean_se(diff)
                row[f"{m}_wins"] = int((diff < 0).sum())
        row["repeats"] = int(g["repeat"].nunique())
        table.append(row)
    return table


def draw(path: Path, table: list[dict[str, Any]], methods: tuple[str, ...], xlabel: str, title: str,
         categorical: bool = False) -> None:  # fmt: skip
    """SS error per time step against the level, mean +- 1 SE, one line per method."""
    levels = [r["level"] for r in table]
    x = np.arange(len(levels), dtype=float) if categorical else np.asarray(levels, dtype=float)
    with figure(8.5, 5.0) as fig:
        ax = fig.subplots()
        width = (x[1] - x[0]) if len(x) > 1 else 1.0
        for k, m in enumerate(methods):
            color, marker = STYLE[m]
            offset = 0.04 * width * (k - (len(methods) - 1) / 2)  # spread the bars
            mean = np.array([r[f"{m}_mean"] for r in table])
            se = np.nan_to_num(np.array([r[f"{m}_se"] for r in table]))
            ax.errorbar(x + offset, mean, yerr=se, color=color, marker=marker, lw=1.4, capsize=3, label=LABELS[m])
        if categorical:
            ax.set_xticks(x, [str(v) for v in levels])
        ax.set_xlabel(xlabel)
        ax.set_ylabel("mean SS error / time step (units)")
        ax.set_yscale("log")
        ax.grid(True, which="both", lw=0.4, alpha=0.5)
        ax.legend(fontsize=8)
        ax.set_title(title, fontsize=10)
        save_png(fig, path)


def sweep_experiment(
    outdir: Path, name: str, title: str, factor: str, levels: tuple[Any, ...], methods: tuple[str, ...], sz: Sizes,
    seed: int, workers: int, xlabel: str, categorical: bool = False, base: Scenario = DEFAULTS,
) -> dict[str, Any]:  # fmt: skip
    """Run the sweep, write `<name>.png`, `<name>.csv` (per level) and `<name>_repeats.csv`; the summary."""
    raw = run_sweep(factor, levels, methods, sz, seed, workers, base)
    table = aggregate(raw, levels, methods)
    files = [f"{name}.png", f"{name}.csv", f"{name}_repeats.csv"]
    save_csv(pd.DataFrame(table), outdir / files[1])
    save_csv(raw, outdir / files[2])
    heading = f"{title}: mean ± 1 SE over {sz.repeats} paired repeats, {sz.iterations} MCMC iterations"
    draw(outdir / files[0], table, methods, xlabel, heading, categorical)
    return {
        "name": name,
        "title": title,
        "files": files,
        "seed": seed,
        "factor": factor,
        "levels": list(levels),
        "methods": list(methods),
        "repeats": sz.repeats,
        "iterations": sz.iterations,
        "defaults": dataclasses.asdict(base),
        "table": table,
    }
