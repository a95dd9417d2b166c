"""Paper Table 1: RMSE of the positions at t = 10, 20, 30 s for Nt = 2, 3, 4 targets with 16
and 64 sensors and 300 particles, for ABC-Rej, ABC-RW and ABC-PT, with the exact-likelihood
MCMC as our reference; our numbers beside the paper's, over R scenarios per cell.

All algorithms of a cell run on the same scenarios, so the paper's ordering
ABC-PT < ABC-RW < ABC-Rej is checked cell by cell on paired differences (mean and standard
error over scenarios). Also reported per algorithm and cell: seconds per scenario, model
simulations per step, acceptance rate, nearest-neighbour fallbacks, ABC-PT swap rate.

    python -m papers.abc --only table1_rmse [--quick] [--out DIR]
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
from .setting import ALGORITHM_ORDER, PAPER_ALGORITHMS, PAPER_TABLE1, TIMES, CellTask, run_task

NAME = "table1_rmse"
SIGNIFICANT_SE = 2.0  # a paired difference counts when it is this many standard errors from 0


@dataclass(frozen=True)
class Sizes:
    scenarios: int
    particles: int = 300
    sensors: tuple[int, ...] = (16, 64)
    targets: tuple[int, ...] = (2, 3, 4)


FULL = Sizes(scenarios=100)
QUICK = Sizes(scenarios=6, particles=100)
SEED = 1


def _ordering(a: np.ndarray, b: np.ndarray) -> dict[str, Any]:
    """mean and se of a - b (paired), and whether a < b holds (significantly, in mean, no)."""
    mean, se = mean_se(a - b)
    if mean < 0 and mean < -SIGNIFICANT_SE * se:
        verdict = "holds"
    elif mean < 0:
        verdict = "holds in mean only"
    elif mean > SIGNIFICANT_SE * se:
        verdict = "reversed"
    else:
        verdict = "fails (not significant)"
    return {"mean": mean, "se": se, "verdict": verdict}


@experiment(FULL, QUICK)
def run(outdir: Path, sz: Sizes, *, seed: int = SEED, workers: int = DEFAULT_WORKERS) -> dict[str, Any]:
    """Write table1_rmse.png, its CSVs and summary into `outdir`."""
    tasks = [
        CellTask(ns, nt, alg, sz.scenarios, sz.particles, seed)
        for nt in sz.targets
        for ns in sz.sensors
        for alg in ALGORITHM_ORDER
    ]
    # heaviest first, so that two workers finish together
    order = sorted(
        range(len(tasks)),
        key=lambda k: -tasks[k].n_sensors * tasks[k].n_targets * (5 if tasks[k].algorithm == "pt" else 1),
    )
    done = pmap(run_task, [tasks[k] for k in order], workers)
    results = {(r["n_sensors"], r["n_targets"], r["algorithm"]): r for r in done}
    cells, orderings, cost = [], [], []
    for nt in sz.targets:
        for ns in sz.sensors:
            for alg in ALGORITHM_ORDER:
                cost.append(_cost_row(nt, ns, alg, results[ns, nt, alg]))
                cells += _cell_rows(nt, ns, alg, results[ns, nt, alg])
            orderings += _ordering_rows(nt, ns, {a: results[ns, nt, a]["rmse"] for a in ALGORITHM_ORDER})
    files = [f"{NAME}.png", f"{NAME}.csv", f"{NAME}_ordering.csv", f"{NAME}_cost.csv"]
    save_csv(pd.DataFrame(cells), outdir / files[1])
    save_csv(pd.DataFrame(orderings), outdir / files[2])
    save_csv(pd.DataFrame(cost), outdir / files[3])
    _draw(outdir / files[0], pd.DataFrame(cells), sz)
    return {
        "name": NAME,
        "title": "Table 1, RMSE for 2-4 targets, 16 and 64 sensors",
        "files": files,
        "seed": seed,
        "scenarios": sz.scenarios,
        "particles": sz.particles,
        "sensors": list(sz.sensors),
        "targets": list(sz.targets),
        "cells": cells,
        "orderings": orderings,
        "cost": cost,
    }


def _cost_row(nt: int, ns: int, alg: str, r: dict[str, Any]) -> dict[str, Any]:
    """One algorithm's compute cost in a cell (`r`: its `run_task` result)."""
    return {
        "n_targets": nt, "n_sensors": ns, "algorithm": alg,
        "seconds_per_scenario": r["seconds_per_scenario"],
        "simulations_per_step": r["simulations_per_step"], "acceptance": r["acceptance"],
        "fallback": r["fallback"], "swap_acceptance": r["swap_acceptance"], "tolerance": r["tolerance"],
    }  # fmt: skip


def _cell_rows(nt: int, ns: int, alg: str, r: dict[str, Any]) -> list[dict[str, Any]]:
    """One algorithm's RMSE at each of TIMES over the scenarios (mean, se, sd), beside the
    paper's Table 1 entry where it has one."""
    rows = []
    for t in TIMES:
        values = r["rmse"][:, t]
        mean, se = mean_se(values)
        paper = PAPER_TABLE1.get((nt, t), {}).get(ns, {}).get(alg)
        rows.append(
            {
                "n_targets": nt, "t": t, "n_sensors": ns, "algorithm": alg, "mean_rmse": mean, "se": se,
                "sd": float(values.std(ddof=1)), "paper_rmse": paper[0] if paper else None,
                "paper_bracket": paper[1] if paper else None,
            }
        )  # fmt: skip
    return rows


def _ordering_rows(nt: int, ns: int, rmse: dict[str, np.ndarray]) -> list[dict[str, Any]]:
    """At each of TIMES, the paired checks ABC-PT < ABC-RW and ABC-RW < ABC-Rej (`rmse`:
    per algorithm, scenarios x time)."""
    rows = []
    for t in TIMES:
        rm = {a: rmse[a][:, t] for a in ALGORITHM_ORDER}
        pt_rw, rw_rej = _ordering(rm["pt"], rm["rw"]), _ordering(rm["rw"], rm["rej"])
        rows.append(
            {
                "n_targets": nt, "t": t, "n_sensors": ns,
                "pt_minus_rw": pt_rw["mean"], "pt_minus_rw_se": pt_rw["se"], "pt_lt_rw": pt_rw["verdict"],
                "rw_minus_rej": rw_rej["mean"], "rw_minus_rej_se": rw_rej["se"], "rw_lt_rej": rw_rej["verdict"],
                "holds": pt_rw["verdict"] == "holds" and rw_rej["verdict"] == "holds",
            }
        )  # fmt: skip
    return rows


def _draw(path: Path, cells: pd.DataFrame, sz: Sizes) -> None:
    colors = {"rej": "0.45", "rw": "tab:blue", "pt": "tab:red", "mcmc": "tab:green"}
    with figure(13.0, 5.2) as fig:
        axes = fig.subplots(1, len(sz.sensors), sharey=True, squeeze=False)[0]
        labels = [f"Nt={nt}\nt={t}" for nt in sz.targets for t in TIMES]
        x = np.arange(len(labels))
        for ax, ns in zip(axes, sz.sensors, strict=True):
            for k, alg in enumerate(ALGORITHM_ORDER):
                g = cells[(cells["n_sensors"] == ns) & (cells["algorithm"] == alg)]
                g = g.set_index(["n_targets", "t"]).loc[[(nt, t) for nt in sz.targets for t in TIMES]]
                dx = 0.18 * (k - 1.5)
                ax.errorbar(x + dx, g["mean_rmse"], yerr=np.nan_to_num(g["se"].to_numpy()), color=colors[alg],
                            marker="o", ms=5, ls="none", capsize=2, label=f"{NAMES[alg]} (ours)")  # fmt: skip
                if alg in PAPER_ALGORITHMS:
                    ax.plot(x + dx, g["paper_rmse"].astype(float), color=colors[alg], marker="D", mfc="none", ms=7,
                            ls="none", label=f"{NAMES[alg]} (paper)")  # fmt: skip
            ax.set_xticks(x, labels, fontsize=8)
            ax.set_title(f"{ns} sensors", fontsize=10)
            ax.grid(True, axis="y", lw=0.4, alpha=0.5)
        axes[0].set_ylabel("position RMSE (units)")
        handles, names = axes[0].get_legend_handles_labels()
        fig.legend(handles, names, loc="outside lower center", ncols=4, fontsize=8.5, frameon=False)
        fig.suptitle(
            f"Table 1: mean RMSE ± 1 SE over {sz.scenarios} scenarios ({sz.particles} particles), filled; the "
            "paper's, open diamonds",
            fontsize=10,
        )
        save_png(fig, path)
