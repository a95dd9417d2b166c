"""Paper Figs. 7-8: the two long sample floats (767, 811): latitude and longitude against
time, ours (ranked model, exact engine, smoothed) vs the labelled filter (the paper's
"hand-labelled" curve, eq. 20) vs the simulated truth the paper never had.

The floats are the sample mission in `data/samples/` (real DIMES geometry, SIMULATED arrival
times, true labels standing in for the hand labels), read with `rafostrack.run.one_float` and
tracked with its `rafostrack.toml` model settings (the ones the arrivals were simulated
with). Both methods use the launch and recovery fixes, as `rafostrack track` does.

    python -m papers.ranked --only fig7_8_floats [--quick] [--out DIR]
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from rafostrack.config import method_overrides, with_overrides
from rafostrack.domain import ArrivalRecord
from rafostrack.plots import date_axis, save_png
from rafostrack.run.method import TrackOutput, track_record
from rafostrack.run.one_float import TrackInputs, load_float
from rafostrack.sim.evaluate import association_accuracy, position_errors_km

from ..common import DEFAULT_WORKERS, experiment, figure, pmap, save_csv
from .setting import ONE_DAY, SAMPLES

NAME = "fig7_8_floats"
RUNNING_DAYS = 15
FLOATS = (("float767", "fig7"), ("float811", "fig8"))
METHODS = ("exact", "labeled")


@dataclass(frozen=True)
class Sizes:
    particles: int
    days: int | None = None  # keep only the first `days` of each record (tests); None = all


FULL = Sizes(particles=1000)
QUICK = Sizes(particles=1000, days=120)  # CI: the full method on the first 120 days of each float
SEED = 0  # the default seed of the published run


def read_truth(float_id: str, samples: Path = SAMPLES) -> pd.DataFrame:
    """The sample's simulated true track: time (UTC, naive), lat, lon."""
    truth = pd.read_csv(samples / "truth" / f"{float_id}.csv")
    truth["time"] = pd.to_datetime(truth["time"], utc=True).dt.tz_localize(None)
    return truth


def load_sample(float_id: str, days: int | None, samples: Path = SAMPLES):
    """The sample float as `rafostrack track` loads it, optionally cut to its first `days`
    (the end fix is then not used: it lies far beyond the kept windows)."""
    loaded = load_float(TrackInputs(samples / f"{float_id}.csv"))
    # As published: calibration estimates every calibrated key, also those the samples'
    # rafostrack.toml sets (which `rafostrack track` keeps as set).
    record, config = loaded.record, dataclasses.replace(loaded.problem.config, explicit=frozenset())
    if days is not None:
        cut = loaded.problem.info.launch_time + days * ONE_DAY
        record = ArrivalRecord(record.float_id, record.path, tuple(w for w in record.windows if w.time <= cut))
        config = with_overrides(config, fixes={"use_end_fix": False})
    return loaded, record, config


def track_sample(task: tuple[str, str, int, int, int | None]) -> TrackOutput:
    """Track one sample float with `method` (smoothed, with the filtered estimate too)."""
    float_id, method, particles, seed, days = task
    loaded, record, config = load_sample(float_id, days)
    config = with_overrides(config, filter={**method_overrides(method), "particles": particles, "seed": seed})
    return track_record(loaded.problem.with_config(config), record, also_filtered=True)


@experiment(FULL, QUICK)
def run(outdir: Path, sz: Sizes, *, seed: int = SEED, workers: int = DEFAULT_WORKERS) -> dict[str, Any]:
    """Write fig7_float767.png, fig8_float811.png, their CSVs and the summary into `outdir`."""
    tasks = [(fid, method, sz.particles, seed, sz.days) for fid, _ in FLOATS for method in METHODS]
    outputs = dict(zip([(t[0], t[1]) for t in tasks], pmap(track_sample, tasks, workers), strict=True))
    files: list[str] = []
    floats: dict[str, Any] = {}
    for fid, fig in FLOATS:
        _, record, _ = load_sample(fid, sz.days)
        truth = read_truth(fid)
        ours, lab = outputs[fid, "exact"], outputs[fid, "labeled"]
        tracks = {
            "exact_smoothed": ours.estimate.track,
            "exact_filtered": ours.filtered.track,
            "labeled_filtered": lab.filtered.track,
            "labeled_smoothed": lab.estimate.track,
        }
        errors = {k: position_errors_km(t, truth) for k, t in tracks.items()}
        table = _float_table(record, truth, tracks, errors)
        png, csv = f"{fig}_{fid}.png", f"{fig}_{fid}.csv"
        save_csv(table, outdir / csv)
        _draw(outdir / png, fid, fig, table, sz.particles)
        files += [png, csv]
        floats[fid] = {"figure": fig, **_float_summary(record, table, tracks, errors, ours, lab)}
    summary = {
        "name": NAME,
        "title": "Figs. 7-8, sample floats 767 and 811",
        "files": files,
        "seed": seed,
        "particles": sz.particles,
        "days": sz.days,
        "floats": floats,
    }
    return summary


def _float_table(
    record: ArrivalRecord, truth: pd.DataFrame, tracks: dict[str, pd.DataFrame], errors: dict[str, np.ndarray]
) -> pd.DataFrame:
    """Per window: the true position, each run's position and error (km), and the stored and
    true signal counts."""
    times = pd.to_datetime(tracks["exact_smoothed"]["time"]).to_numpy()
    true_at = truth.set_index("time").loc[times]
    table = pd.DataFrame({"time": times, "lat_true": true_at["lat"].to_numpy(), "lon_true": true_at["lon"].to_numpy()})
    for k, t in tracks.items():
        table[f"lat_{k}"] = t["lat"].to_numpy()
        table[f"lon_{k}"] = t["lon"].to_numpy()
        table[f"err_km_{k}"] = errors[k]
    table["n_stored"] = [w.n_signals for w in record.windows]
    table["n_true"] = [sum(b is not None for b in (w.beacon_id or ())) for w in record.windows]
    return table


def _float_summary(
    record: ArrivalRecord,
    table: pd.DataFrame,
    tracks: dict[str, pd.DataFrame],
    errors: dict[str, np.ndarray],
    ours: TrackOutput,
    lab: TrackOutput,
) -> dict[str, Any]:
    """One float's scores: each run's RMSE and largest error (overall, and on the windows with
    fewer than 3 true signals and the others), our labels' accuracy, the windows flagged
    ambiguous, ours against the labelled filter, and the seconds each method took."""
    few = table["n_true"].to_numpy() < 3
    ours_vs_labeled = position_errors_km(tracks["exact_smoothed"], _as_truth(tracks["labeled_filtered"]))
    return {
        "windows": len(record.windows),
        "rmse_km": {k: float(np.sqrt(np.mean(e**2))) for k, e in errors.items()},
        "max_err_km": {k: float(e.max()) for k, e in errors.items()},
        "windows_lt3_true": int((table["n_true"] < 3).sum()),
        "rmse_km_lt3": {k: _rms(e[few]) for k, e in errors.items()},
        "rmse_km_ge3": {k: _rms(e[~few]) for k, e in errors.items()},
        "label_accuracy": {
            "exact_smoothed": association_accuracy(ours.estimate.labels, record),
            "exact_filtered": association_accuracy(ours.filtered.labels, record),
        },
        "ambiguous_windows": {
            "exact_smoothed": int(ours.estimate.track["ambiguous"].sum()),
            "exact_filtered": int(ours.filtered.track["ambiguous"].sum()),
        },
        "rmse_ours_vs_labeled_km": float(np.sqrt(np.mean(ours_vs_labeled**2))),
        "seconds": {
            "exact": round(ours.seconds.filter_s + ours.seconds.smoother_s, 1),
            "labeled": round(lab.seconds.filter_s + lab.seconds.smoother_s, 1),
        },
    }


def _rms(e: np.ndarray) -> float:
    return float(np.sqrt(np.mean(e**2))) if len(e) else float("nan")


def _as_truth(track: pd.DataFrame) -> pd.DataFrame:
    return pd.DataFrame({"time": pd.to_datetime(track["time"]), "lat": track["lat"], "lon": track["lon"]})


def _draw(path: Path, fid: str, fig_name: str, table: pd.DataFrame, particles: int) -> None:
    from matplotlib.patches import Patch

    t = table["time"].to_numpy()
    number = fig_name.removeprefix("fig")
    with figure(12.0, 8.0) as fig:
        ax_lon, ax_lat, ax_err = fig.subplots(3, 1, sharex=True, height_ratios=[1.0, 1.0, 0.8])
        for ax, coord in ((ax_lon, "lon"), (ax_lat, "lat")):
            ax.plot(t, table[f"{coord}_true"], "-", color="k", lw=2.6, alpha=0.35, label="simulated truth")
            ax.plot(
                t,
                table[f"{coord}_labeled_filtered"],
                "-",
                color="tab:blue",
                lw=1.0,
                label="labelled filter (paper's hand-labelled curve)",
            )
            ax.plot(
                t, table[f"{coord}_exact_smoothed"], "-", color="tab:red", lw=1.0, label="ours: ranked, exact, smoothed"
            )
            ax.grid(True, lw=0.4, alpha=0.5)
        ax_lon.set_ylabel("longitude (°E)")
        ax_lat.set_ylabel("latitude (°N)")
        ax_lon.legend(loc="best", fontsize=8.5, framealpha=0.9)
        styles = (
            ("labeled_filtered", "tab:blue", "-", "labelled filter"),
            ("exact_filtered", "tab:orange", "-", "ours, filtered"),
            ("exact_smoothed", "tab:red", "-", "ours, smoothed"),
        )
        for key, color, ls, label in styles:
            e = table[f"err_km_{key}"].to_numpy()
            running = np.sqrt(pd.Series(e**2).rolling(RUNNING_DAYS, center=True, min_periods=1).mean())
            ax_err.plot(t, running, ls, color=color, lw=1.1, label=f"{label} (RMSE {np.sqrt(np.mean(e**2)):.1f} km)")
        few = table["n_true"].to_numpy() < 3
        for k in np.flatnonzero(few):
            ax_err.axvspan(t[k] - np.timedelta64(12, "h"), t[k] + np.timedelta64(12, "h"), color="0.88", lw=0, zorder=0)
        ax_err.set_ylim(bottom=0)
        ax_err.set_ylabel(f"error (km), {RUNNING_DAYS}-day\nrunning RMS")
        ax_err.grid(True, lw=0.4, alpha=0.5)
        handles, _ = ax_err.get_legend_handles_labels()
        handles.append(Patch(color="0.88", label="day with < 3 true signals stored"))
        ax_err.legend(
            handles=handles, loc="lower center", bbox_to_anchor=(0.5, 1.0), fontsize=8, ncols=4, frameon=False
        )
        date_axis(ax_err.xaxis)
        fig.suptitle(
            f"Fig. {number}: float {fid.removeprefix('float')} (sample: real DIMES geometry, simulated arrivals), "
            f"{len(t)} daily windows, {particles} particles",
            fontsize=11,
        )
        save_png(fig, path)
