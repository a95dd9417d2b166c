"""Figs. 4 and 5: one target on a line or a spiral, its track and its labelled arrivals."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from rafostrack.plots import save_png

from ..common import experiment, figure, pmap, save_csv
from .setting import LOST_UNITS, ONE_DAY, T0, Scenario, data_rng, make_scenario, method_task, true_signal_counts


@dataclass(frozen=True)
class TrajectorySizes:
    days: int
    particles: int
    clutter_rate: float = 4.0  # the paper's Poisson(4), Pc = 0.8


@dataclass(frozen=True)
class TrajectoryFigure:
    """One of the paper's single-target figures: a name, a trajectory shape, a title and
    the sizes of the full and the quick run."""

    name: str
    shape: str  # "line" or "spiral" (`setting.make_scenario`)
    title: str
    full: TrajectorySizes
    quick: TrajectorySizes

    def run(self, outdir: Path, **options: Any) -> dict[str, Any]:
        """Write `<name>.png` and its CSVs into `outdir`; return the summary (also as JSON)."""
        return experiment(self.full, self.quick)(self._run)(outdir, **options)

    def _run(self, outdir: Path, sz: TrajectorySizes, *, seed: int = 0, workers: int = 2) -> dict[str, Any]:
        return run_trajectory(self.name, self.shape, self.title, outdir, sz, seed=seed, workers=workers)


def run_trajectory(
    name: str,
    shape: str,
    title: str,
    outdir: Path,
    sz: TrajectorySizes,
    *,
    seed: int,
    workers: int,
) -> dict[str, Any]:
    """Simulate one target on `shape` at clutter Poisson(4), track it with the ranked model
    (exact engine; filtered = the paper's estimate, smoothed = ours), the unranked baseline
    and the labelled filter, and draw the track and the labelled arrival times."""
    from rafostrack.sim.evaluate import association_accuracy

    scenario = make_scenario(shape, sz.days)
    config = scenario.config(sz.clutter_rate, particles=sz.particles, seed=seed)
    record = scenario.simulate(config, data_rng(seed, sz.clutter_rate))
    methods = ("exact", "unranked", "labeled")
    runs = dict(zip(methods, pmap(method_task, [(scenario, record, config, m) for m in methods], workers), strict=True))
    ours = runs["exact"]
    n_true = true_signal_counts(record)
    n_stored = np.array([w.n_signals for w in record.windows])
    table = _track_table(scenario, runs, n_stored, n_true)
    arrivals = _arrivals_table(scenario, record, ours)
    files = [f"{name}.png", f"{name}_track.csv", f"{name}_arrivals.csv"]
    save_csv(table, outdir / files[1])
    save_csv(arrivals, outdir / files[2])
    acc_s = association_accuracy(ours.output.estimate.labels, record)
    acc_f = association_accuracy(ours.output.filtered.labels, record)
    _draw_trajectory(outdir / files[0], scenario, table, arrivals, title, sz, acc_s)
    track_f, track_s = ours.output.filtered.track, ours.output.estimate.track
    return {
        "name": name,
        "title": title,
        "files": files,
        "seed": seed,
        "days": scenario.days,
        "particles": sz.particles,
        "clutter_rate": sz.clutter_rate,
        "step_km": round(scenario.step_km, 2),
        "diffusion_km_per_day": scenario.diffusion_km_per_day,
        "mapping": scenario.setting.describe(),
        "stored_per_window": float(n_stored.mean()),
        "clutter_fraction": float(1.0 - n_true.sum() / max(n_stored.sum(), 1)),
        "frac_windows_lt3_true": float(np.mean(n_true < 3)),
        **_error_summary(runs, scenario.setting.unit_km),
        "ambiguous_windows": {
            "exact_filtered": int(track_f["ambiguous"].sum()),
            "exact_smoothed": int(track_s["ambiguous"].sum()),
        },
        "max_err_km_smoothed": float(np.sqrt(ours.sq_err_smoothed.max()) * scenario.setting.unit_km),
        "label_accuracy": {"filtered": acc_f, "smoothed": acc_s},
        "label_errors_smoothed": _label_errors(arrivals),
    }


def _track_table(scenario: Scenario, runs: dict[str, Any], n_stored: NDArray, n_true: NDArray) -> pd.DataFrame:
    """Per day: the true position and the filtered, smoothed and unranked estimates (paper
    units), each method's error (units) and the stored and true signal counts."""
    setting, ours, unranked = scenario.setting, runs["exact"], runs["unranked"]
    track_f, track_s = ours.output.filtered.track, ours.output.estimate.track
    xf, yf = setting.to_plane(track_f["lat"], track_f["lon"])
    xs, ys = setting.to_plane(track_s["lat"], track_s["lon"])
    xb, yb = setting.to_plane(unranked.output.filtered.track["lat"], unranked.output.filtered.track["lon"])
    truth_xy = scenario.xy[1:]
    return pd.DataFrame(
        {
            "day": np.arange(1, scenario.days + 1),
            "x_true": truth_xy[:, 0],
            "y_true": truth_xy[:, 1],
            "x_filtered": xf,
            "y_filtered": yf,
            "x_smoothed": xs,
            "y_smoothed": ys,
            "x_unranked": xb,
            "y_unranked": yb,
            "err_filtered_units": np.sqrt(ours.sq_err_filtered),
            "err_smoothed_units": np.sqrt(ours.sq_err_smoothed),
            "err_unranked_units": np.sqrt(unranked.sq_err_filtered),
            "err_labeled_units": np.sqrt(runs["labeled"].sq_err_filtered),
            "n_stored": n_stored,
            "n_true": n_true,
        }
    )


def _arrivals_table(scenario: Scenario, record: Any, ours: Any) -> pd.DataFrame:
    """Per stored TOA: its day, rank and time (s and paper units), its true beacon and our
    smoothed (with its probability) and filtered labels ("" = clutter)."""
    truth_labels = [b for w in record.windows for b in (w.beacon_id or ())]
    labels = ours.output.estimate.labels
    return pd.DataFrame(
        {
            "day": [(w.time - T0) // ONE_DAY for w in record.windows for _ in range(w.n_signals)],
            "rank": labels["rank"].to_numpy(),
            "toa_s": labels["toa_s"].to_numpy(),
            "toa_units": labels["toa_s"].to_numpy() / scenario.setting.unit_s,
            "true_beacon": [b or "" for b in truth_labels],
            "label_smoothed": [b if isinstance(b, str) else "" for b in labels["beacon_id"]],
            "prob_smoothed": labels["prob"].to_numpy(),
            "label_filtered": [b if isinstance(b, str) else "" for b in ours.output.filtered.labels["beacon_id"]],
        }
    )


def _label_errors(arrivals: pd.DataFrame) -> dict[str, int]:
    """Our smoothed labels' errors by kind: a beacon for another, clutter called a beacon, a
    beacon called clutter; and the stored TOAs."""
    wrong = arrivals["true_beacon"] != arrivals["label_smoothed"]
    return {
        "beacon_swapped": int((wrong & (arrivals["true_beacon"] != "") & (arrivals["label_smoothed"] != "")).sum()),
        "clutter_as_beacon": int((wrong & (arrivals["true_beacon"] == "")).sum()),
        "beacon_as_clutter": int((wrong & (arrivals["label_smoothed"] == "")).sum()),
        "stored": len(arrivals),
    }


def _error_summary(runs: dict[str, Any], unit_km: float) -> dict[str, dict[str, float]]:
    """Each method's MSE (units^2), RMSE (km) and fraction of days lost (error over
    LOST_UNITS)."""
    ours, unranked, labeled = runs["exact"], runs["unranked"], runs["labeled"]

    def units_rmse(sq: NDArray) -> float:
        return float(np.sqrt(sq.mean()))

    return {
        "mse_units2": {
            "exact_filtered": float(ours.sq_err_filtered.mean()),
            "exact_smoothed": float(ours.sq_err_smoothed.mean()),
            "unranked_filtered": float(unranked.sq_err_filtered.mean()),
            "unranked_smoothed": float(unranked.sq_err_smoothed.mean()),
            "labeled_filtered": float(labeled.sq_err_filtered.mean()),
            "labeled_smoothed": float(labeled.sq_err_smoothed.mean()),
        },
        "rmse_km": {
            "exact_filtered": units_rmse(ours.sq_err_filtered) * unit_km,
            "exact_smoothed": units_rmse(ours.sq_err_smoothed) * unit_km,
            "unranked_filtered": units_rmse(unranked.sq_err_filtered) * unit_km,
            "labeled_filtered": units_rmse(labeled.sq_err_filtered) * unit_km,
        },
        "lost_frac": {
            key: float(np.mean(sq > LOST_UNITS**2))
            for key, sq in (
                ("exact_filtered", ours.sq_err_filtered),
                ("exact_smoothed", ours.sq_err_smoothed),
                ("unranked_filtered", unranked.sq_err_filtered),
            )
        },
    }


def _draw_trajectory(
    path: Path, scenario: Scenario, table: pd.DataFrame, arrivals: pd.DataFrame, title: str, sz: Any, acc: float
) -> None:
    """The figure: (a) the true and estimated tracks on the plane, (b) the stored arrival
    times coloured by their true beacon, our wrong labels circled."""
    from rafostrack.plots import beacon_colors

    ids = [str(b) for b in scenario.beacons.beacon_id]
    colors = beacon_colors(ids)
    with figure(13.0, 5.6) as fig:
        ax_map, ax_toa = fig.subplots(1, 2, width_ratios=[1.0, 1.35])
        _draw_track_panel(ax_map, scenario, table, title, ids, colors)
        _draw_arrivals_panel(ax_toa, scenario, arrivals, sz, acc, ids, colors)
        save_png(fig, path)


def _draw_track_panel(
    ax: Any, scenario: Scenario, table: pd.DataFrame, title: str, ids: list[str], colors: dict[str, Any]
) -> None:
    """Panel (a): the beacons, the true track and the filtered, smoothed and unranked ones."""
    bxy = scenario.setting.beacon_xy()
    for k, b in enumerate(ids):
        ax.plot(*bxy[k], "^", color=colors[b], ms=9, mec="k", mew=0.6, zorder=5)
        ax.annotate(b, bxy[k], xytext=(4, 4), textcoords="offset points", fontsize=8)
    ax.plot(scenario.xy[:, 0], scenario.xy[:, 1], "-", color="k", lw=2.2, label="truth", zorder=2)
    ax.plot(*scenario.xy[0], "o", color="k", ms=6, zorder=6)
    for key, style, color, width, label in (
        ("unranked", ":", "0.5", 1.2, "unranked baseline (filtered)"),
        ("filtered", "-", "tab:orange", 1.2, "ranked, exact, filtered (paper)"),
        ("smoothed", "-", "tab:blue", 1.5, "ranked, exact, smoothed (ours)"),
    ):
        ax.plot(table[f"x_{key}"], table[f"y_{key}"], style, color=color, lw=width, label=label)
    est = table[["x_filtered", "y_filtered", "x_smoothed", "y_smoothed", "x_unranked", "y_unranked"]].to_numpy()
    lo = max(min(-0.05, float(np.nanmin(est)) - 0.02), -0.5)
    hi = min(max(1.05, float(np.nanmax(est)) + 0.02), 1.5)
    ax.set_xlim(lo, hi)
    ax.set_ylim(lo, hi)
    ax.set_aspect("equal")
    ax.set_xlabel("x (paper units)")
    ax.set_ylabel("y (paper units)")
    ax.grid(True, lw=0.4, alpha=0.5)
    ax.legend(loc="lower right", fontsize=8, framealpha=0.9)
    ax.set_title(f"(a) {title}: true vs estimated track", fontsize=10)


def _draw_arrivals_panel(
    ax: Any, scenario: Scenario, arrivals: pd.DataFrame, sz: Any, acc: float, ids: list[str], colors: dict[str, Any]
) -> None:
    """Panel (b): each beacon's true arrival curve (range = arrival time in paper units), the
    stored TOAs coloured by their true beacon, clutter as crosses, our wrong labels circled."""
    from matplotlib.lines import Line2D

    setting = scenario.setting
    bxy = setting.beacon_xy()
    days = np.arange(0, scenario.days + 1)
    pred = np.hypot(scenario.xy[:, None, 0] - bxy[None, :, 0], scenario.xy[:, None, 1] - bxy[None, :, 1])
    for k, b in enumerate(ids):
        ax.plot(days, pred[:, k], "-", color=colors[b], lw=0.8, alpha=0.6, zorder=1)
    true_b = arrivals["true_beacon"].to_numpy()
    est_b = arrivals["label_smoothed"].to_numpy()
    x, t = arrivals["day"].to_numpy(), arrivals["toa_units"].to_numpy()
    clutter = true_b == ""
    ax.scatter(x[clutter], t[clutter], marker="x", s=18, c="0.35", linewidths=0.9, zorder=3)
    for b in ids:
        sel = true_b == b
        if sel.any():
            ax.scatter(x[sel], t[sel], s=18, color=colors[b], edgecolors="none", zorder=4)
    wrong = true_b != est_b
    ax.scatter(x[wrong], t[wrong], s=70, facecolors="none", edgecolors="red", linewidths=1.1, zorder=5)
    ax.set_ylim(0.0, setting.window_units)
    ax.set_xlim(0, scenario.days + 1)
    ax.set_xlabel("time step (day)")
    ax.set_ylabel("arrival time (paper units = distance)")
    ax.grid(True, lw=0.4, alpha=0.5)
    handles = [
        Line2D([], [], color="0.3", lw=0.8, label="true arrival curve (colour = beacon)"),
        Line2D([], [], ls="none", marker="o", color="tab:blue", label="stored TOA, colour = true beacon"),
        Line2D([], [], ls="none", marker="x", color="0.35", label="stored clutter"),
        Line2D([], [], ls="none", marker="o", mfc="none", mec="red", ms=9, label="our smoothed label is wrong"),
    ]
    ax.legend(handles=handles, loc="upper right", fontsize=8, framealpha=0.9)
    ax.set_title(
        f"(b) stored arrival times (first {setting.max_signals}), clutter Poisson({sz.clutter_rate:g}), "
        f"Pd {setting.p_detect:g}; labels {acc:.1%} right",
        fontsize=10,
    )


# Quick mode (CI) runs exactly the full runs here: one target each, and the particle count,
# trajectory and clutter are what the method's behaviour depends on (at 400 particles the quick
# figures showed the method failing where the full ones did not).
LINE = TrajectoryFigure(
    "fig4_line", "line", "Fig. 4, straight line", TrajectorySizes(60, 1000), TrajectorySizes(60, 1000)
)
SPIRAL = TrajectoryFigure(
    "fig5_spiral", "spiral", "Fig. 5, spiral", TrajectorySizes(120, 1000), TrajectorySizes(120, 1000)
)
