"""Paper Fig. 12 (appendix A.3): float 759, whose record has stretches with at most two true
signals, where the position is not determined. Several runs with different seeds of the
labelled filter (the paper's "simple particle filter on hand labels", eq. 20) and of ours
(ranked model, exact engine, smoothed; the filtered estimate too), against the simulated
truth.

Where the position is not determined, runs with different seeds disagree and the
posterior is wide or split in two. The tool flags a window `ambiguous` (track column, with
`second_mode_km` and both modes in the modes table) when its weighted particle cloud splits
into two separated modes (docs/method.md). Reported: the days flagged per run, the
between-seed spread (RMS distance of the runs' positions from their mean) and the
posterior sd, over the days with fewer than 3 true signals stored and elsewhere.

    python -m papers.ranked --only fig12_ambiguity [--quick] [--out DIR]
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from rafostrack.model.geodesy import local_offsets_km
from rafostrack.plots import date_axis, save_png
from rafostrack.sim.evaluate import position_errors_km
from rafostrack.summaries.estimates import runs_of

from ..common import DEFAULT_WORKERS, experiment, figure, pmap, save_csv
from .fig7_8_floats import load_sample, read_truth, track_sample
from .setting import span_text, true_signal_counts

NAME = "fig12_ambiguity"
FLOAT_ID = "float759"
# (key, method, estimate): the runs drawn and scored
RUNS = (
    ("labeled_filtered", "labeled", "filtered"),
    ("exact_filtered", "exact", "filtered"),
    ("exact_smoothed", "exact", "smoothed"),
)


@dataclass(frozen=True)
class Sizes:
    seeds: int
    particles: int
    days: int | None = None


FULL = Sizes(seeds=5, particles=1000)
QUICK = Sizes(seeds=2, particles=1000, days=150)  # CI: fewer seeds, the first 150 days, the full method
SEED = 0  # the default seed of the published run


def spread_km(lat: np.ndarray, lon: np.ndarray) -> np.ndarray:
    """Per day (rows), RMS distance (km) of the runs (columns) from their mean position."""
    out = np.empty(lat.shape[0])
    for k in range(lat.shape[0]):
        east, north = local_offsets_km(lat[k], lon[k], float(lat[k].mean()), float(lon[k].mean()))
        e, n = np.asarray(east), np.asarray(north)
        out[k] = np.sqrt(np.mean((e - e.mean()) ** 2 + (n - n.mean()) ** 2))
    return out


@experiment(FULL, QUICK)
def run(outdir: Path, sz: Sizes, *, seed: int = SEED, workers: int = DEFAULT_WORKERS) -> dict[str, Any]:
    """Write fig12_ambiguity.png, its CSVs and summary into `outdir`."""
    seeds = [seed + k for k in range(sz.seeds)]
    tasks = [(FLOAT_ID, method, sz.particles, s, sz.days) for method in ("labeled", "exact") for s in seeds]
    outputs = dict(zip([(t[1], t[3]) for t in tasks], pmap(track_sample, tasks, workers), strict=True))
    _, record, _ = load_sample(FLOAT_ID, sz.days)
    truth = read_truth(FLOAT_ID)
    n_true = true_signal_counts(record)
    few = n_true < 3

    tracks = {
        (key, s): (outputs[method, s].estimate if est == "smoothed" else outputs[method, s].filtered).track
        for key, method, est in RUNS
        for s in seeds
    }
    times = pd.to_datetime(tracks["exact_smoothed", seeds[0]]["time"]).to_numpy()
    true_at = truth.set_index("time").loc[times]
    table = pd.DataFrame(
        {"time": times, "n_true": n_true, "lat_true": true_at["lat"].to_numpy(), "lon_true": true_at["lon"].to_numpy()}
    )
    runs_rows = []
    stats: dict[str, Any] = {}
    for key, _, _ in RUNS:
        rows, stats[key] = _score_runs(table, key, seeds, [tracks[key, s] for s in seeds], truth, times, few)
        runs_rows += rows
    files = [f"{NAME}.png", f"{NAME}.csv", f"{NAME}_runs.csv"]
    save_csv(table, outdir / files[1])
    save_csv(pd.DataFrame(runs_rows), outdir / files[2])
    _draw(outdir / files[0], table, seeds, sz.particles, few)
    return {
        "name": NAME,
        "title": "Fig. 12, float 759: where the position is not determined",
        "files": files,
        "seed": seed,
        "seeds": seeds,
        "particles": sz.particles,
        "windows": len(record.windows),
        "windows_lt3_true": int(few.sum()),
        "windows_le1_true": int((n_true <= 1).sum()),
        **_few_signal_stretches(times, few),
        "runs": stats,
    }


def _score_runs(
    table: pd.DataFrame,
    key: str,
    seeds: list[int],
    tracks: list[pd.DataFrame],
    truth: pd.DataFrame,
    times: np.ndarray,
    few: np.ndarray,
) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """One kind of run (`key`) over the seeds (`tracks`, one per seed): add its positions,
    between-seed spread, mean sd and ambiguous-run count to `table`; return a row per seed
    (flagged windows, RMSE) and the kind's statistics (`_run_stats`)."""
    lat = np.column_stack([t["lat"].to_numpy() for t in tracks])
    lon = np.column_stack([t["lon"].to_numpy() for t in tracks])
    sd = np.column_stack([t["sd_km"].to_numpy() for t in tracks])
    amb = np.column_stack([t["ambiguous"].to_numpy() for t in tracks])
    err = np.column_stack([position_errors_km(t, truth) for t in tracks])
    spread = spread_km(lat, lon)
    for j, s in enumerate(seeds):
        table[f"lat_{key}_seed{s}"] = lat[:, j]
        table[f"lon_{key}_seed{s}"] = lon[:, j]
    table[f"spread_km_{key}"] = spread
    table[f"sd_km_{key}_mean"] = sd.mean(axis=1)
    table[f"ambiguous_runs_{key}"] = amb.sum(axis=1)
    rows = []
    for j, s in enumerate(seeds):
        second = tracks[j]["second_mode_km"].to_numpy()[amb[:, j]]
        rows.append(
            {
                "run": key,
                "seed": s,
                "ambiguous_windows": int(amb[:, j].sum()),
                "ambiguous_days": span_text(runs_of(times, amb[:, j]), limit=50),
                "second_mode_km": " ".join(f"{x:.1f}" for x in second),
                "rmse_km": float(np.sqrt(np.mean(err[:, j] ** 2))),
            }
        )
    seconds_modes = np.concatenate([t["second_mode_km"].to_numpy()[amb[:, j]] for j, t in enumerate(tracks)])
    return rows, _run_stats(times, amb, seconds_modes, spread, sd, err, few)


def _run_stats(
    times: np.ndarray,
    amb: np.ndarray,
    seconds_modes: np.ndarray,
    spread: np.ndarray,
    sd: np.ndarray,
    err: np.ndarray,
    few: np.ndarray,
) -> dict[str, Any]:
    """A kind of run's statistics over its seeds (columns of `amb`, `sd`, `err`): windows
    flagged ambiguous, the between-seed spread, the posterior sd and the error, on the days
    with fewer than 3 true signals (`few`) and elsewhere."""
    flagged_any = amb.any(axis=1)
    return {
        "ambiguous_windows_per_run": [int(x) for x in amb.sum(axis=0)],
        "second_mode_km_max": float(seconds_modes.max()) if len(seconds_modes) else float("nan"),
        "ambiguous_days_any_run": span_text(runs_of(times, flagged_any), limit=30),
        "ambiguous_windows_any_run": int(flagged_any.sum()),
        "ambiguous_windows_all_runs": int(amb.all(axis=1).sum()),
        "ambiguous_in_lt3_stretches": int((flagged_any & few).sum()),
        "spread_km_lt3": float(np.mean(spread[few])) if few.any() else float("nan"),
        "spread_km_ge3": float(np.mean(spread[~few])),
        "spread_km_max": float(spread.max()),
        "spread_max_day": str(np.datetime_as_string(times[int(np.argmax(spread))], "D")),
        "sd_km_lt3": float(np.mean(sd[few])) if few.any() else float("nan"),
        "sd_km_ge3": float(np.mean(sd[~few])),
        "rmse_km_mean": float(np.mean(np.sqrt(np.mean(err**2, axis=0)))),
        "err_km_lt3": float(np.sqrt(np.mean(err[few] ** 2))) if few.any() else float("nan"),
        "err_km_ge3": float(np.sqrt(np.mean(err[~few] ** 2))),
    }


def _few_signal_stretches(times: np.ndarray, few: np.ndarray) -> dict[str, Any]:
    """The stretches with < 3 true signals (where Fig. 12's question is asked): all, the
    longest (2 days or more), and the longest's length in days."""
    stretches = sorted(runs_of(times, few), key=lambda ab: ab[1] - ab[0], reverse=True)
    long_ones = [ab for ab in stretches if (ab[1] - ab[0]) / np.timedelta64(1, "D") >= 2]
    return {
        "lt3_stretches": span_text(sorted(runs_of(times, few)), limit=40),
        "longest_lt3_stretches": span_text(sorted(long_ones[:8])),
        "longest_lt3_days": int((stretches[0][1] - stretches[0][0]) / np.timedelta64(1, "D")) + 1 if stretches else 0,
    }


# Each run kind's colour and label in the figure.
STYLE = {
    "labeled_filtered": ("tab:blue", "labelled filter (paper's hand-labelled PF)"),
    "exact_filtered": ("tab:orange", "ours, filtered"),
    "exact_smoothed": ("tab:red", "ours, smoothed"),
}


def _draw(path: Path, table: pd.DataFrame, seeds: list[int], particles: int, few: np.ndarray) -> None:
    """The figure: longitude and latitude against time (truth, every seed's run, the days
    flagged ambiguous), then the spread between seeds and the posterior sd; the days with
    < 3 true signals shaded."""
    t = table["time"].to_numpy()
    with figure(12.0, 9.0) as fig:
        ax_lon, ax_lat, ax_sp = fig.subplots(3, 1, sharex=True, height_ratios=[1.0, 1.0, 0.9])
        for ax in (ax_lon, ax_lat, ax_sp):
            for k in np.flatnonzero(few):
                ax.axvspan(t[k] - np.timedelta64(12, "h"), t[k] + np.timedelta64(12, "h"), color="0.88", lw=0, zorder=0)
            ax.grid(True, lw=0.4, alpha=0.5)
        _draw_positions(ax_lon, ax_lat, t, table, seeds)
        _draw_spread(ax_sp, t, table)
        fig.suptitle(
            f"Fig. 12: float 759 (sample, simulated arrivals), {len(t)} windows, {int(few.sum())} with < 3 true "
            f"signals; {len(seeds)} seeds x {particles} particles",
            fontsize=11,
        )
        save_png(fig, path)


def _draw_positions(ax_lon: Any, ax_lat: Any, t: np.ndarray, table: pd.DataFrame, seeds: list[int]) -> None:
    """Longitude and latitude panels: the truth, each seed's labelled and smoothed runs, and
    the windows ours flags ambiguous in any seed (circled), with the legend."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    for ax, coord in ((ax_lon, "lon"), (ax_lat, "lat")):
        ax.plot(t, table[f"{coord}_true"], "-", color="k", lw=2.6, alpha=0.35, zorder=1)
        for key in ("labeled_filtered", "exact_smoothed"):
            color, _ = STYLE[key]
            for s in seeds:
                ax.plot(t, table[f"{coord}_{key}_seed{s}"], "-", color=color, lw=0.8, alpha=0.75, zorder=2)
        amb = table["ambiguous_runs_exact_smoothed"].to_numpy() > 0
        ax.plot(
            t[amb],
            table[f"{coord}_exact_smoothed_seed{seeds[0]}"].to_numpy()[amb],
            "o",
            mfc="none",
            mec="m",
            ms=8,
            zorder=3,
        )
    ax_lon.set_ylabel("longitude (°E)")
    ax_lat.set_ylabel("latitude (°N)")
    handles = [
        Line2D([], [], color="k", lw=2.6, alpha=0.35, label="simulated truth"),
        Line2D([], [], color="tab:blue", lw=0.8, label=f"labelled filter, {len(seeds)} seeds"),
        Line2D([], [], color="tab:red", lw=0.8, label=f"ours (exact, smoothed), {len(seeds)} seeds"),
        Line2D([], [], ls="none", marker="o", mfc="none", mec="m", ms=8, label="flagged ambiguous (ours, any seed)"),
        Patch(color="0.88", label="< 3 true signals stored"),
    ]
    ax_lon.legend(handles=handles, loc="best", fontsize=8, ncols=2, framealpha=0.9)


def _draw_spread(ax: Any, t: np.ndarray, table: pd.DataFrame) -> None:
    """Bottom panel (log km): each run kind's spread between seeds, and the posterior sd of
    ours (smoothed) and of the labelled filter."""
    for key in ("labeled_filtered", "exact_filtered", "exact_smoothed"):
        color, label = STYLE[key]
        ax.plot(t, table[f"spread_km_{key}"], "-", color=color, lw=1.0, label=f"{label}: spread between seeds")
    ax.plot(
        t,
        table["sd_km_exact_smoothed_mean"],
        "--",
        color="tab:red",
        lw=1.0,
        label="ours, smoothed: posterior sd (mean over seeds)",
    )
    ax.plot(
        t,
        table["sd_km_labeled_filtered_mean"],
        "--",
        color="tab:blue",
        lw=1.0,
        label="labelled filter: posterior sd",
    )
    ax.set_yscale("log")
    ax.set_ylabel("km")
    ax.legend(loc="lower center", bbox_to_anchor=(0.5, 1.0), fontsize=8, ncols=3, frameon=False)
    date_axis(ax.xaxis)
