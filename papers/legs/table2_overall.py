"""Paper Table 2: 200 random scenarios, sigma^2 ~ U(0, 1600), T ~ U(50, 500) s,
dT ~ U(1, 20) s, noise type uniform over {Gaussian, Uniform, Gamma, Beta}.

Per method: mean SS error and SS error per time step (with 95% intervals, mean +- 1.96 SE);
per pair (RW vs the Kalman filter, paired on each scenario's SS / time): the win
percentage with its 95% Wilson interval and the average win amount (the mean decrease
in SS / time over the scenarios each side won) with its standard error.

    python -m papers.legs --only table2_overall [--quick] [--out DIR]
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from rafostrack.plots import save_png

from ..common import DEFAULT_WORKERS, experiment, figure, mean_se, pmap, save_csv
from .methods import LABELS, run_methods
from .sweep import STYLE
from .target import NOISE_TYPES, Scenario, make_run

NAME = "table2_overall"
METHODS = ("rw_paper", "rw_ours", "kf", "ks")
PAIRS = (("rw_paper", "kf"), ("rw_ours", "kf"), ("rw_ours", "rw_paper"), ("rw_ours", "ks"))
PAPER = {"rw_paper": {"ss": 2362.4, "ss_per_time": 11.8, "win": 0.76, "avg_win": 4.6},
         "kf": {"ss": 3189.7, "ss_per_time": 16.0, "win": 0.24, "avg_win": 0.5}}  # fmt: skip


@dataclass(frozen=True)
class Sizes:
    scenarios: int
    iterations: int


FULL = Sizes(scenarios=200, iterations=5000)
QUICK = Sizes(scenarios=16, iterations=1500)
SEED = 200


def draw_scenario(rng: np.random.Generator) -> Scenario:
    """The paper's random scenario (module docstring)."""
    sigma2 = rng.uniform(0.0, 1600.0)
    total = rng.uniform(50.0, 500.0)
    interval = rng.uniform(1.0, 20.0)
    return Scenario(total_s=total, sigma2=sigma2, interval_s=interval, noise=NOISE_TYPES[rng.integers(4)])


def _task(task: tuple[int, int, int]) -> list[dict[str, Any]]:
    i, seed, iterations = task
    rng = np.random.default_rng([seed, i])
    scenario = draw_scenario(rng)
    run = make_run(scenario, rng)
    meta = {"scenario": i, "sigma2": scenario.sigma2, "total_s": scenario.total_s,
            "interval_s": scenario.interval_s, "noise": scenario.noise, "measurements": len(run.meas_t)}  # fmt: skip
    return [{**meta, **row} for row in run_methods(run, iterations, [seed, i, 1], METHODS)]


def wilson(successes: int, n: int, z: float = 1.959964) -> tuple[float, float]:
    """Wilson score 95% interval of a binomial proportion."""
    if n == 0:
        return math.nan, math.nan
    p = successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return centre - half, centre + half


def compare(wide: pd.DataFrame, a: str, b: str) -> dict[str, Any]:
    """Paired comparison of a and b on SS / time (module docstring)."""
    diff = wide[b] - wide[a]  # > 0: a better
    n = len(diff)
    wins = int((diff > 0).sum())
    lo, hi = wilson(wins, n)
    a_amount, a_se = mean_se(diff[diff > 0])
    b_amount, b_se = mean_se(-diff[diff < 0])
    mean_diff, mean_diff_se = mean_se(diff)
    return {"a": a, "b": b, "n": n, "a_wins": wins, "a_win_rate": wins / n if n else math.nan,
            "a_win_rate_ci95": [lo, hi], "a_avg_win": a_amount, "a_avg_win_se": a_se,
            "b_avg_win": b_amount, "b_avg_win_se": b_se, "mean_b_minus_a": mean_diff,
            "mean_b_minus_a_se": mean_diff_se}  # fmt: skip


@experiment(FULL, QUICK)
def run(outdir: Path, sz: Sizes, *, seed: int = SEED, workers: int = DEFAULT_WORKERS) -> dict[str, Any]:
    raw = pd.DataFrame([row for rows in pmap(_task, [(i, seed, sz.iterations) for i in range(sz.scenarios)], workers)
                        for row in rows])  # fmt: skip
    methods = {}
    for m in METHODS:
        g = raw[raw["method"] == m]
        ss, ss_se = mean_se(g["ss"])
        per, per_se = mean_se(g["ss_per_time"])
        sec, _ = mean_se(g["seconds"])
        methods[m] = {"ss": ss, "ss_ci95": 1.959964 * ss_se, "ss_per_time": per, "ss_per_time_ci95": 1.959964 * per_se,
                      "median_ss_per_time": float(g["ss_per_time"].median()), "seconds": sec}  # fmt: skip
    wide = raw.pivot_table(index="scenario", columns="method", values="ss_per_time")
    pairs = [compare(wide, a, b) for a, b in PAIRS]
    by_noise = {
        str(noise): {m: float(g.loc[g["method"] == m, "ss_per_time"].mean()) for m in METHODS}
        | {"n": int(g["scenario"].nunique())}
        for noise, g in raw.groupby("noise")
    }
    files = [f"{NAME}.png", f"{NAME}.csv"]
    save_csv(raw, outdir / files[1])
    _draw(outdir / files[0], wide, sz)
    return {
        "name": NAME,
        "title": "Table 2, 200 random scenarios",
        "files": files,
        "seed": seed,
        "scenarios": sz.scenarios,
        "iterations": sz.iterations,
        "methods": methods,
        "pairs": pairs,
        "by_noise": by_noise,
        "paper": PAPER,
    }


def _draw(path: Path, wide: pd.DataFrame, sz: Sizes) -> None:
    """Each scenario's SS / time, RW against the Kalman filter (below the diagonal: RW wins)."""
    with figure(7.0, 6.0) as fig:
        ax = fig.subplots()
        for m in ("rw_paper", "rw_ours"):
            color, marker = STYLE[m]
            ax.scatter(wide["kf"], wide[m], s=14, color=color, marker=marker, alpha=0.7, label=LABELS[m])
        top = float(np.nanmax(wide[["kf", "rw_paper", "rw_ours"]].to_numpy())) * 1.2
        bottom = max(float(np.nanmin(wide[["kf", "rw_paper", "rw_ours"]].to_numpy())) / 1.2, 1e-2)
        ax.plot([bottom, top], [bottom, top], color="0.3", lw=1, ls="--")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel(f"{LABELS['kf']}: SS error / time step")
        ax.set_ylabel("RW: SS error / time step")
        ax.legend(fontsize=8)
        ax.grid(True, which="both", lw=0.4, alpha=0.5)
        ax.set_title(f"Table 2 scenarios (n = {sz.scenarios}, {sz.iterations} iterations): below the line RW wins",
                     fontsize=10)  # fmt: skip
        save_png(fig, path)
