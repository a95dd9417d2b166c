"""Paper Fig. 8: SS error per time step and run time against the number of MCMC iterations N,
at the paper's default settings (T 200 s, sigma^2 5, dT 5 s, Gaussian).

Each repeat simulates one run and fits it with the paper's sampler and ours at every N
(paired); the Kalman filter's error on the same runs is the reference line.

    python -m papers.legs --only fig8_iterations [--quick] [--out DIR]
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from rafostrack.plots import save_png

from ..common import DEFAULT_WORKERS, experiment, figure, mean_se, pmap, save_csv
from .methods import LABELS, run_methods
from .sweep import STYLE
from .target import Scenario, make_run

NAME = "fig8_iterations"
SAMPLERS = ("rw_paper", "rw_ours")


@dataclass(frozen=True)
class Sizes:
    repeats: int
    iterations: tuple[int, ...]


FULL = Sizes(repeats=6, iterations=(500, 1000, 2500, 5000, 10000, 20000))
QUICK = Sizes(repeats=2, iterations=(250, 1000, 3000))
SEED = 800


def _task(task: tuple[int, int, tuple[int, ...]]) -> list[dict[str, Any]]:
    rep, seed, levels = task
    run = make_run(Scenario(), np.random.default_rng([seed, rep]))
    rows = [{"iterations": 0, "repeat": rep, **r} for r in run_methods(run, 1, [seed, rep, 0], ("kf",))]
    for i, n in enumerate(levels):
        for r in run_methods(run, n, [seed, rep, i + 1], SAMPLERS):
            rows.append({"iterations": n, "repeat": rep, **r})
    return rows


@experiment(FULL, QUICK)
def run(outdir: Path, sz: Sizes, *, seed: int = SEED, workers: int = DEFAULT_WORKERS) -> dict[str, Any]:
    raw = pd.DataFrame([row for rows in pmap(_task, [(r, seed, sz.iterations) for r in range(sz.repeats)], workers)
                        for row in rows])  # fmt: skip
    table = []
    for n in sz.iterations:
        row: dict[str, Any] = {"iterations": n}
        for m in SAMPLERS:
            g = raw[(raw["iterations"] == n) & (raw["method"] == m)]
            row[f"{m}_mean"], row[f"{m}_se"] = mean_se(g["ss_per_time"])
            row[f"{m}_seconds"], row[f"{m}_seconds_se"] = mean_se(g["seconds"])
        table.append(row)
    kf_mean, kf_se = mean_se(raw.loc[raw["method"] == "kf", "ss_per_time"])
    files = [f"{NAME}.png", f"{NAME}.csv", f"{NAME}_repeats.csv"]
    save_csv(pd.DataFrame(table), outdir / files[1])
    save_csv(raw, outdir / files[2])
    _draw(outdir / files[0], table, kf_mean, sz)
    return {
        "name": NAME,
        "title": "Fig. 8, iterations",
        "files": files,
        "seed": seed,
        "repeats": sz.repeats,
        "levels": list(sz.iterations),
        "kf_mean": kf_mean,
        "kf_se": kf_se,
        "table": table,
    }


def _draw(path: Path, table: list[dict[str, Any]], kf_mean: float, sz: Sizes) -> None:
    n = np.array([r["iterations"] for r in table], dtype=float)
    with figure(8.5, 5.0) as fig:
        ax = fig.subplots()
        right = ax.twinx()
        for m in SAMPLERS:
            color, marker = STYLE[m]
            mean = np.array([r[f"{m}_mean"] for r in table])
            se = np.nan_to_num(np.array([r[f"{m}_se"] for r in table]))
            ax.errorbar(n, mean, yerr=se, color=color, marker=marker, lw=1.4, capsize=3, label=f"{LABELS[m]}: error")
            right.plot(
                n, [r[f"{m}_seconds"] for r in table], color=color, ls=":", marker=".", label=f"{LABELS[m]}: time"
            )
        ax.axhline(kf_mean, color=STYLE["kf"][0], ls="--", lw=1, label=f"{LABELS['kf']}: error")
        ax.set_xscale("log")
        ax.set_xlabel("MCMC iterations N")
        ax.set_ylabel("mean SS error / time step (units)")
        right.set_ylabel("run time per fit (s, dotted)")
        ax.grid(True, which="both", lw=0.4, alpha=0.5)
        lines = ax.get_legend_handles_labels()
        more = right.get_legend_handles_labels()
        ax.legend(lines[0] + more[0], lines[1] + more[1], fontsize=8, loc="upper right")
        ax.set_title(f"Fig. 8: error and run time against N, mean ± 1 SE over {sz.repeats} paired repeats", fontsize=10)
        save_png(fig, path)
