"""Paper Fig. 6b: mean squared error against the clutter parameter lambda, ranked model vs
the unranked baseline (eq. 19), with the exact and BP engines and the labelled filter as a
lower bound; filtered (the paper's estimate) and smoothed.

The target follows the straight line of Fig. 6a (= Fig. 4's). For each lambda, R repeats;
a repeat simulates one record (its own seed) and tracks it with every method, so the
methods are compared on the same data (paired). MSE of one repeat = the mean over windows
of the squared position error, in squared paper units. Reported per lambda: mean MSE over
repeats, its standard error (sd / sqrt(R)), the median, and the fraction of windows where
the error exceeds 0.1 units (the target lost); and the paired difference unranked - exact
with its standard error.

    python -m papers.ranked --only fig6b_clutter [--quick] [--out DIR]
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from rafostrack.plots import save_png

from ..common import DEFAULT_WORKERS, experiment, figure, mean_se, pmap, save_csv
from .setting import CLUTTER_LEVELS, LOST_UNITS, line_record, make_scenario, run_method

NAME = "fig6b_clutter"
# (method, smoothed too?): BP is filtered only, as in the paper.
METHODS = (("exact", True), ("bp", False), ("unranked", True), ("labeled", True))
STYLE = {
    "exact": ("tab:blue", "o", "ranked, exact"),
    "bp": ("tab:purple", "s", "ranked, BP (paper's engine)"),
    "unranked": ("tab:red", "v", "unranked baseline (eq. 19)"),
    "labeled": ("tab:green", "D", "labelled (lower bound)"),
}


@dataclass(frozen=True)
class Sizes:
    repeats: int
    particles: int
    days: int = 60
    lambdas: tuple[float, ...] = CLUTTER_LEVELS


FULL = Sizes(repeats=24, particles=1000)
# Quick (CI): fewer repeats and clutter levels, never a smaller run: every quick run is one of
# the full runs (same particles, days and seeds), so quick numbers are a subset of the full ones.
QUICK = Sizes(repeats=2, particles=1000, lambdas=(2.0, 8.0))
SEED = 100  # the default seed of the published run


def _repeat(task: tuple[float, int, int, int, int]) -> list[dict[str, Any]]:
    """Every method on one simulated record (lambda, repeat)."""
    lam, rep, seed, days, particles = task
    scenario, config, record = line_record(days, lam, particles, seed + rep, seed, lam, rep)
    rows = []
    for method, smooth in METHODS:
        r = run_method(scenario, record, config, method, smooth=smooth)
        rows.append(
            {
                "lambda": lam,
                "repeat": rep,
                "method": method,
                "mse_filtered": float(r.sq_err_filtered.mean()),
                "mse_smoothed": float(r.sq_err_smoothed.mean()) if smooth else np.nan,
                "lost_filtered": float(np.mean(r.sq_err_filtered > LOST_UNITS**2)),
                "lost_smoothed": float(np.mean(r.sq_err_smoothed > LOST_UNITS**2)) if smooth else np.nan,
                "seconds": r.seconds,
            }
        )
    return rows


def aggregate(raw: pd.DataFrame) -> pd.DataFrame:
    """Per lambda, method and estimate: mean MSE, se, median, R, lost fraction."""
    out = []
    for (lam, method), g in raw.groupby(["lambda", "method"], sort=True):
        for est in ("filtered", "smoothed"):
            v = g[f"mse_{est}"].dropna()
            if v.empty:
                continue
            mean, se = mean_se(v)
            out.append(
                {
                    "lambda": lam,
                    "method": method,
                    "estimate": est,
                    "mean_mse": mean,
                    "se_mse": se,
                    "median_mse": float(v.median()),
                    "R": len(v),
                    "lost_frac": float(g[f"lost_{est}"].mean()),
                    "seconds_per_run": float(g["seconds"].mean()),
                }
            )
    return pd.DataFrame(out)


def paired(raw: pd.DataFrame, a: str, b: str, est: str) -> pd.DataFrame:
    """Per lambda: mean and se over repeats of MSE(a) - MSE(b) on the same records."""
    wide = raw.pivot_table(index=["lambda", "repeat"], columns="method", values=f"mse_{est}")
    rows = []
    for lam, g in wide.groupby(level="lambda"):
        diff = (g[a] - g[b]).dropna()
        mean, se = mean_se(diff)
        rows.append(
            {
                "lambda": lam,
                "a": a,
                "b": b,
                "estimate": est,
                "mean_diff": mean,
                "se_diff": se,
                "a_better_repeats": int((diff < 0).sum()),
                "R": len(diff),
            }
        )
    return pd.DataFrame(rows)


@experiment(FULL, QUICK)
def run(outdir: Path, sz: Sizes, *, seed: int = SEED, workers: int = DEFAULT_WORKERS) -> dict[str, Any]:
    """Write fig6b_clutter.png, its CSVs and summary into `outdir`."""
    tasks = [(float(lam), rep, seed, sz.days, sz.particles) for lam in sz.lambdas for rep in range(sz.repeats)]
    raw = pd.DataFrame([row for rows in pmap(_repeat, tasks, workers) for row in rows])
    agg = aggregate(raw)
    diffs = pd.concat(
        [
            paired(raw, "unranked", "exact", "filtered"),
            paired(raw, "unranked", "exact", "smoothed"),
            paired(raw, "bp", "exact", "filtered"),
        ],
        ignore_index=True,
    )
    files = [f"{NAME}.png", f"{NAME}.csv", f"{NAME}_paired.csv", f"{NAME}_repeats.csv"]
    save_csv(agg, outdir / files[1])
    save_csv(diffs, outdir / files[2])
    save_csv(raw, outdir / files[3])
    scenario = make_scenario("line", sz.days)
    _draw(outdir / files[0], agg, sz, scenario.step_km)

    def cell(method: str, est: str, lam: float, col: str) -> float:
        sel = agg[(agg["method"] == method) & (agg["estimate"] == est) & (agg["lambda"] == lam)]
        return float(sel[col].iloc[0]) if len(sel) else float("nan")

    table = []
    for lam in sz.lambdas:
        row: dict[str, Any] = {"lambda": float(lam)}
        for method, smooth in METHODS:
            for est in ("filtered", "smoothed") if smooth else ("filtered",):
                for col in ("mean_mse", "se_mse", "median_mse", "lost_frac"):
                    row[f"{method}_{est}_{col}"] = cell(method, est, lam, col)
        for est in ("filtered", "smoothed"):
            d = diffs[(diffs["a"] == "unranked") & (diffs["estimate"] == est) & (diffs["lambda"] == lam)].iloc[0]
            row[f"diff_unranked_minus_exact_{est}"] = float(d["mean_diff"])
            row[f"diff_unranked_minus_exact_{est}_se"] = float(d["se_diff"])
            row[f"exact_better_repeats_{est}"] = int(d["R"] - d["a_better_repeats"])
        d = diffs[(diffs["a"] == "bp") & (diffs["lambda"] == lam)].iloc[0]
        row["diff_bp_minus_exact_filtered"] = float(d["mean_diff"])
        row["diff_bp_minus_exact_filtered_se"] = float(d["se_diff"])
        table.append(row)
    summary = {
        "name": NAME,
        "title": "Fig. 6b, MSE against clutter",
        "files": files,
        "seed": seed,
        "repeats": sz.repeats,
        "particles": sz.particles,
        "days": sz.days,
        "lambdas": [float(x) for x in sz.lambdas],
        "step_km": round(scenario.step_km, 2),
        "diffusion_km_per_day": scenario.diffusion_km_per_day,
        "mapping": scenario.setting.describe(),
        "lost_units": LOST_UNITS,
        "table": table,
    }
    return summary


def _draw(path: Path, agg: pd.DataFrame, sz: Sizes, step_km: float) -> None:
    lams = np.array(sorted(agg["lambda"].unique()), dtype=float)
    with figure(12.5, 5.2) as fig:
        axes = fig.subplots(1, 2, sharey=True)
        for ax, est, title in (
            (axes[0], "filtered", "(a) filtered: the paper's estimate"),
            (axes[1], "smoothed", "(b) smoothed (ours; BP not smoothed)"),
        ):
            methods = [m for m, smooth in METHODS if est == "filtered" or smooth]
            for k, method in enumerate(methods):
                g = agg[(agg["method"] == method) & (agg["estimate"] == est)].sort_values("lambda")
                if g.empty:
                    continue
                color, marker, label = STYLE[method]
                x = g["lambda"].to_numpy() * 2 ** (0.06 * (k - (len(methods) - 1) / 2))  # spread the bars
                mean, se = g["mean_mse"].to_numpy(), np.nan_to_num(g["se_mse"].to_numpy())
                lower = np.minimum(se, 0.95 * mean)  # a log axis cannot show a bar below 0
                ax.errorbar(x, mean, yerr=[lower, se], color=color, marker=marker, ms=6, lw=1.4, capsize=3, label=label)
                ax.plot(x, g["median_mse"], ls="none", marker=marker, mfc="none", mec=color, ms=9, alpha=0.7)
            ax.set_xscale("log", base=2)
            ax.set_yscale("log")
            ax.set_xticks(lams, [f"{x:g}" for x in lams])
            ax.set_xlabel("clutter parameter λ (Poisson mean per window; Pc = λ / (1 + λ))")
            ax.grid(True, which="both", lw=0.4, alpha=0.5)
            ax.set_title(title, fontsize=10)
        axes[0].set_ylabel("mean squared error (paper units²)")
        handles, labels = axes[0].get_legend_handles_labels()
        from matplotlib.lines import Line2D

        handles.append(Line2D([], [], ls="none", marker="o", mfc="none", mec="0.3", ms=9))
        labels.append("open marker: median over repeats")
        fig.legend(handles, labels, loc="outside lower center", ncols=5, fontsize=8.5, frameon=False)
        fig.suptitle(
            f"Fig. 6b: straight line, {sz.days} steps of {step_km:.1f} km; mean ± 1 SE over R = {sz.repeats} "
            f"repeats; {sz.particles} particles",
            fontsize=11,
        )
        save_png(fig, path)
