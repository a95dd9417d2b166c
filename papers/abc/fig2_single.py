"""Paper Fig. 2: RMSE of the position of one target over time, 64 sensors, for the MCMC
with the exact likelihood (eq. 6), ABC-RW and ABC-PT (and ABC-Rej, not in the paper's
figure), with 95% confidence bands of the mean over R scenarios.

Every algorithm runs on the same R scenarios. Reported at t = 10, 20, 30 s: mean RMSE
over scenarios and its standard error, the paired differences between algorithms, the
acceptance rates and the compute cost.

    python -m papers.abc --only fig2_single [--quick] [--out DIR]
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from rafostrack.plots import save_png
from rafostrack.sensors import NAMES

from ..common import DEFAULT_WORKERS, experiment, figure, mean_se, pmap, save_csv
from .setting import TIMES, CellTask, run_task

NAME = "fig2_single"
ALGORITHMS = ("mcmc", "pt", "rw", "rej")
STYLE = {
    "mcmc": ("tab:green", "o"),
    "pt": ("tab:red", "x"),
    "rw": ("tab:blue", "^"),
    "rej": ("0.5", "s"),
}
N_SENSORS = 64


@dataclass(frozen=True)
class Sizes:
    scenarios: int
    particles: int = 300


FULL = Sizes(scenarios=200)
QUICK = Sizes(scenarios=24, particles=200)
SEED = 2


@experiment(FULL, QUICK)
def run(outdir: Path, sz: Sizes, *, seed: int = SEED, workers: int = DEFAULT_WORKERS) -> dict[str, Any]:
    """Write fig2_single.png, its CSV and summary into `outdir`."""
    tasks = [CellTask(N_SENSORS, 1, a, sz.scenarios, sz.particles, seed) for a in ALGORITHMS]
    results = {r["algorithm"]: r for r in pmap(run_task, tasks, workers)}
    rows = []
    for alg, r in results.items():
        for t in range(r["rmse"].shape[1]):
            mean, se = mean_se(r["rmse"][:, t])
            rows.append(
                {"algorithm": alg, "t": t, "mean_rmse": mean, "se": se, "sd": float(r["rmse"][:, t].std(ddof=1))}
            )
    curve = pd.DataFrame(rows)
    files = [f"{NAME}.png", f"{NAME}.csv"]
    save_csv(curve, outdir / files[1])
    _draw(outdir / files[0], curve, sz)
    at: dict[str, dict[str, Any]] = {}
    for alg, r in results.items():
        at[alg] = {
            "name": NAMES[alg],
            "acceptance": r["acceptance"],
            "fallback": r["fallback"],
            "swap_acceptance": r["swap_acceptance"],
            "seconds_per_scenario": r["seconds_per_scenario"],
            "simulations_per_step": r["simulations_per_step"],
            "tolerance": r["tolerance"],
        }
        for t in TIMES:
            at[alg][f"rmse_t{t}"], at[alg][f"se_t{t}"] = mean_se(r["rmse"][:, t])
    diffs = {}
    for a, b in (("pt", "rw"), ("mcmc", "pt"), ("mcmc", "rw"), ("rw", "rej")):
        for t in TIMES:
            diffs[f"{a}_minus_{b}_t{t}"] = mean_se(results[a]["rmse"][:, t] - results[b]["rmse"][:, t])
    return {
        "name": NAME,
        "title": "Fig. 2, one target, 64 sensors",
        "files": files,
        "seed": seed,
        "scenarios": sz.scenarios,
        "particles": sz.particles,
        "algorithms": at,
        "paired": {k: {"mean": m, "se": s} for k, (m, s) in diffs.items()},
    }


def _draw(path: Path, curve: pd.DataFrame, sz: Sizes) -> None:
    with figure(8.5, 5.2) as fig:
        ax = fig.subplots()
        for alg in ALGORITHMS:
            g = curve[curve["algorithm"] == alg].sort_values("t")
            color, marker = STYLE[alg]
            t, mean, se = g["t"].to_numpy(), g["mean_rmse"].to_numpy(), np.nan_to_num(g["se"].to_numpy())
            ax.plot(
                t, mean, color=color, marker=marker, ms=4, lw=1.3, label=NAMES[alg], ls="--" if alg == "rej" else "-"
            )
            ax.fill_between(t, mean - 1.96 * se, mean + 1.96 * se, color=color, alpha=0.18, lw=0)
        ax.set_xlabel("time (s)")
        ax.set_ylabel("position RMSE (units)")
        ax.grid(True, lw=0.4, alpha=0.5)
        ax.legend(fontsize=9, frameon=False, loc="upper left")
        ax.set_title(
            f"Fig. 2: one target, {N_SENSORS} sensors; mean over {sz.scenarios} scenarios, 95% band of the mean; "
            f"{sz.particles} particles",
            fontsize=10,
        )
        save_png(fig, path)
