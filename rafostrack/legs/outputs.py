"""A float's leg fit as files: legs.parquet, legs_track.parquet, legs.png, legs_run.json.

- legs.parquet: one row per leg of the MAP trajectory: start and end (UTC) with 95%
  intervals (the nearest change time in each posterior sample), the mean velocity over
  the leg's span in each sample as speed (km/day) and compass heading (degrees clockwise
  from north) with 95% intervals, east/north velocity, and the leg's end points.
- legs_track.parquet: the usual track schema (`summaries.estimates.TRACK_COLUMNS`) at each window:
  the float's posterior position (its leg's position plus its wiggle, given the window:
  mean and covariance ellipse), the chain's effective sample size of the leg position,
  plus the leg velocity there (posterior mean and sd, km/day).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from .. import __version__
from ..errors import kind_of
from ..io.writers import file_digest, write_json, write_parquet
from ..run.one_float import LoadedFloat, TrackInputs
from ..summaries.estimates import TRACK_COLUMNS
from .evidence import grid_loglik, window_positions
from .fit import LegFit
from .summaries import leg_table, position_samples, sample_ess
from .trajectory import positions, velocities

DAY_NS = np.timedelta64(86_400_000_000_000, "ns")


def to_time(fit: LegFit, days: NDArray | float) -> NDArray[np.datetime64]:
    """Days since the launch as UTC times."""
    return fit.epoch + np.round(np.asarray(days, dtype=float) * 86400e9).astype("timedelta64[ns]")


def bearing_deg(angle_rad: NDArray | float) -> NDArray:
    """Math angle (counter-clockwise from east) as a compass bearing (clockwise from north)."""
    return (90.0 - np.degrees(np.asarray(angle_rad))) % 360.0


def legs_frame(fit: LegFit) -> pd.DataFrame:
    table = leg_table(fit.chain)
    best = fit.chain.best
    lat, lon = fit.plane.from_plane(best.knots)
    vel = best.velocities
    return pd.DataFrame(
        {
            "float_id": fit.float_id,
            "leg": np.arange(1, len(table) + 1),
            "start": to_time(fit, table["start"]),
            "start_lo": to_time(fit, table["start_lo"]),
            "start_hi": to_time(fit, table["start_hi"]),
            "end": to_time(fit, table["end"]),
            "end_lo": to_time(fit, table["end_lo"]),
            "end_hi": to_time(fit, table["end_hi"]),
            "duration_days": table["end"] - table["start"],
            "speed_km_per_day": table["speed"],
            "speed_lo_km_per_day": table["speed_lo"],
            "speed_hi_km_per_day": table["speed_hi"],
            "heading_deg": bearing_deg(table["heading_rad"]),
            "heading_lo_deg": bearing_deg(table["heading_hi_rad"]),  # a larger math angle is a smaller bearing
            "heading_hi_deg": bearing_deg(table["heading_lo_rad"]),
            "map_east_km_per_day": vel[:, 0],
            "map_north_km_per_day": vel[:, 1],
            "start_lat": lat[:-1],
            "start_lon": lon[:-1],
            "end_lat": lat[1:],
            "end_lon": lon[1:],
        }
    )


def float_positions(fit: LegFit, max_samples: int = 200, chunk: int = 20) -> tuple[NDArray, NDArray]:
    """Posterior mean (W, 2) and covariance (W, 2, 2) of the float's position at each window:
    over up to `max_samples` kept samples, the conditional moments given the sample's leg
    position and wiggle sd (`evidence.window_positions`), combined by total variance."""
    chain, ev = fit.chain, fit.evidence
    pick = np.unique(np.linspace(0, len(chain.samples) - 1, min(len(chain.samples), max_samples)).round().astype(int))
    rows = np.arange(len(fit.window_days))
    means = np.empty((len(pick), len(rows), 2))
    covs = np.empty((len(pick), len(rows), 2, 2))
    for lo in range(0, len(pick), chunk):
        part = pick[lo : lo + chunk]
        legs_xy = np.stack([positions(chain.samples[i], fit.window_days) for i in part])
        for level in np.unique(chain.levels[part]):
            sel = np.flatnonzero(chain.levels[part] == level)
            m, c = window_positions(ev.grids, rows, legs_xy[sel], ev.wiggle_sd_km[level])
            means[lo + sel], covs[lo + sel] = m, c
    mean = means.mean(axis=0)
    dev = means - mean
    cov = covs.mean(axis=0) + np.einsum("swi,swj->wij", dev, dev) / max(len(pick) - 1, 1)
    return mean, cov


def track_frame(fit: LegFit) -> pd.DataFrame:
    days = fit.window_days
    samples = position_samples(fit.chain, days)  # (S, W, 2) leg positions
    mean, cov = float_positions(fit)
    values, vectors = np.linalg.eigh(cov)
    values = np.clip(values, 0.0, None)
    major = vectors[:, :, 1]
    lat, lon = fit.plane.from_plane(mean)
    rows = np.arange(len(days))
    loglik = grid_loglik(fit.evidence.grids, rows, mean, fit.evidence.outside_sd_km)
    vel = np.stack([velocities(legs, days) for legs in fit.chain.samples])
    n_signals = np.array([w.n_signals for w in fit.windows], dtype=np.int64)
    frame = pd.DataFrame(
        {
            "float_id": fit.float_id,
            "time": to_time(fit, days),
            "lat": lat,
            "lon": lon,
            "sd_km": np.sqrt(np.trace(cov, axis1=1, axis2=2)),
            "smaj_km": np.sqrt(values[:, 1]),
            "smin_km": np.sqrt(values[:, 0]),
            "angle_deg": np.degrees(np.arctan2(major[:, 0], major[:, 1])) % 180.0,
            "ess": np.minimum(sample_ess(samples[:, :, 0]), sample_ess(samples[:, :, 1])),
            "n_signals": n_signals,
            "loglik": loglik,
            "ambiguous": False,
            "second_mode_km": np.nan,
            "status": np.where(n_signals > 0, "ok", "unsupported"),
            "east_km_per_day": vel[:, :, 0].mean(axis=0),
            "north_km_per_day": vel[:, :, 1].mean(axis=0),
            "east_sd_km_per_day": vel[:, :, 0].std(axis=0),
            "north_sd_km_per_day": vel[:, :, 1].std(axis=0),
        }
    )
    assert list(frame.columns[: len(TRACK_COLUMNS)]) == list(TRACK_COLUMNS)
    return frame


def run_record(fit: LegFit, loaded: LoadedFloat, inputs: TrackInputs, total_s: float) -> dict[str, Any]:
    """The legs_run.json payload; its warnings (reading the inputs, then the smoother's) each
    with its kind (`warning_kinds`, in the same order)."""
    k = fit.chain.n_legs
    warnings = [*loaded.warnings.messages, *fit.smoother.warnings]
    files = {"float_file": inputs.float_path, "beacons": inputs.resolved_beacons()}
    floats_path = inputs.resolved_floats()
    if floats_path is not None:
        files["floats"] = floats_path
    return {
        "rafostrack_version": __version__,
        "float_id": fit.float_id,
        "inputs": {name: {"path": str(p), "sha256": file_digest(p)} for name, p in files.items()},
        "config": loaded.problem.config.to_dict(),
        "windows": len(fit.windows),
        "runtime_s": round(total_s, 3),
        "timings_s": {name: round(v, 3) for name, v in fit.timings.items()},
        "iterations": loaded.problem.config.legs.iterations,
        "kept_samples": len(fit.chain.samples),
        "acceptance": {m: round(a, 4) for m, a in fit.chain.acceptance.items()},
        "steps": {m: round(float(v), 4) for m, v in fit.chain.steps.items()},
        "wiggle_sd_km": {
            "levels": list(fit.evidence.wiggle_sd_km),
            "posterior_mean": round(float(np.mean(np.array(fit.evidence.wiggle_sd_km)[fit.chain.levels])), 3),
            "posterior_probability": [
                round(float(np.mean(fit.chain.levels == i)), 3) for i in range(fit.evidence.n_levels)
            ],
        },
        "legs": {
            "map": fit.chain.best.n_legs,
            "start": fit.start.n_legs,
            "posterior_mean": round(float(k.mean()), 2),
            "posterior_q05": int(np.quantile(k, 0.05)),
            "posterior_q95": int(np.quantile(k, 0.95)),
        },
        "smoother_calibration": fit.smoother.calibration,
        "warnings": warnings,
        "warning_kinds": [kind_of(message) for message in warnings],
    }


def write_outputs(
    fit: LegFit, loaded: LoadedFloat, inputs: TrackInputs, out_dir: Path, *, plots: bool, total_s: float
) -> dict[str, Any]:
    """Write every output atomically; return the run record."""
    meta = {"version": __version__, "estimate": "legs", "config": loaded.problem.config.to_dict()}
    write_parquet(legs_frame(fit), out_dir / "legs.parquet", meta)
    track = track_frame(fit)
    write_parquet(track, out_dir / "legs_track.parquet", meta)
    if plots:
        plot_legs(fit, track, out_dir / "legs.png")
    run = run_record(fit, loaded, inputs, total_s)
    write_json(out_dir / "legs_run.json", run)
    return run


def plot_legs(fit: LegFit, track: pd.DataFrame, path: Path) -> Path:
    """Map of the leg track (posterior mean, MAP knots) over the smoother's; speed against time."""
    from ..plots import date_axis, figure, save_png

    smoother = fit.smoother.track
    ref = float(smoother["lon"].iloc[0])

    def unwrap(lon: NDArray | pd.Series) -> NDArray:
        return ref + (np.asarray(lon, dtype=float) - ref + 180.0) % 360.0 - 180.0

    knot_lat, knot_lon = fit.plane.from_plane(fit.chain.best.knots)
    speed = np.hypot(track["east_km_per_day"], track["north_km_per_day"])
    speed_sd = np.sqrt(track["east_sd_km_per_day"] ** 2 + track["north_sd_km_per_day"] ** 2)
    with figure(13.0, 5.5) as fig:
        left, right = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1.1, 1.4]})
        left.plot(unwrap(smoother["lon"]), smoother["lat"], color="0.6", lw=0.8, label="particle smoother")
        left.plot(unwrap(track["lon"]), track["lat"], color="tab:blue", lw=1.2, label="legs: posterior mean")
        left.plot(
            unwrap(knot_lon), knot_lat, "o", color="tab:red", ms=3, label=f"MAP knots ({fit.chain.best.n_legs} legs)"
        )
        left.set_xlabel("longitude (°)")
        left.set_ylabel("latitude (°)")
        left.set_aspect(1.0 / max(math.cos(math.radians(float(smoother["lat"].mean()))), 0.1))
        left.legend(fontsize=8)
        left.set_title(f"{fit.float_id}: leg track", fontsize=10)
        times = pd.to_datetime(track["time"])
        right.fill_between(times, np.maximum(speed - 2 * speed_sd, 0), speed + 2 * speed_sd, color="tab:blue",
                           alpha=0.2, label="± 2 sd")  # fmt: skip
        right.plot(times, speed, color="tab:blue", lw=1.2, label="legs: speed")
        right.set_ylabel("speed (km/day)")
        right.legend(fontsize=8)
        right.grid(True, lw=0.4, alpha=0.5)
        date_axis(right.xaxis)
        right.set_title("leg speed at each window (posterior mean ± 2 sd)", fontsize=10)
        save_png(fig, path)
    return path
