"""The method on floats: a simulated RAFOS float drifting along a ridge, with a gap in its
record, tracked by rafostrack with and without the bathymetry constraint.

The ridge runs north-south 40 km east of the launch; its depth is 4000 - 3700 exp(-(x / 40
km)^2) m at x km east of the crest, written as a GEBCO-like NetCDF grid (`elevation`,
positive up, 2 arc-minute cells) and read back through `rafostrack.context.bathymetry`. The
float drifts at 1000 m: the sea floor is shallower than the float within ~18 km of the crest.
Truth: the tracker's own integrated Ornstein-Uhlenbeck drift (velocity sd 4 km/day,
decorrelation 10 days) with a mean current of 2 km/day east and 2 km/day north, pushing the
float against the ridge; a daily step that would put it where the sea floor is within 100 m
of its depth is drawn again, so the float slides along the flank. Arrivals: the package's
simulator (`simulate.simulate_arrivals`, the synthetic 8-beacon ring), one window a day; the
windows of days 30-44 are removed (a 15-day gap in the record: one motion step for the
filter) and those of days 45-59 hold nothing (the float listened and heard nothing: sources
off), a 30-day stretch without a fix. Tracking:
`run.method.track_record` with the simulation's model, calibration off (so that both runs use
the same model), the mean current known, and `[context] bathymetry` set or not.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from rafostrack.config import load_config
from rafostrack.domain import ArrivalRecord, FloatInfo, Particles, Window
from rafostrack.model.geodesy import displace, local_offsets_km
from rafostrack.motion import IntegratedOU
from rafostrack.plots import save_png
from rafostrack.sim.scenarios import synthetic_scenario
from rafostrack.sim.simulate import simulate_arrivals

from ..common import experiment, figure, mean_se, pmap, save_csv

FLOAT_DEPTH_M = 1000.0
# The tracker's default depth model gives the grid at the float's depth an sd of
# sqrt(50^2 + (0.03 x 1000)^2) = 58 m (`context.floats.depth_sd_m`, without slope and spread):
# a position where the true sea floor is shallower than the float by more than twice that
# (CF < 0.03 under the model) is one the tracker calls forbidden.
FORBIDDEN_MARGIN_M = 2.0 * float(np.hypot(50.0, 0.03 * FLOAT_DEPTH_M))
RIDGE_OFFSET_KM = 40.0
RIDGE_WIDTH_KM = 40.0
CLEARANCE_M = 100.0
GAP_DAYS = (30, 45, 60)  # no windows on days 30..44 (one motion step), empty ones on days 45..59
CURRENT_KM_PER_DAY = (2.0, 2.0)
EDDY_SD_KM_PER_DAY, EDDY_DAYS = 4.0, 10.0  # the truth's eddy velocity sd and time scale


@dataclass(frozen=True)
class Sizes:
    repeats: int
    days: int
    particles: int


FULL = Sizes(repeats=8, days=90, particles=600)
QUICK = Sizes(repeats=1, days=70, particles=250)


def ridge_depth_m(lat: NDArray, lon: NDArray, info: FloatInfo) -> NDArray[np.float64]:
    """The true sea-floor depth (module docstring)."""
    crest_lat, crest_lon = displace(info.launch_lat, info.launch_lon, RIDGE_OFFSET_KM, 0.0)
    east, _ = local_offsets_km(lat, lon, float(crest_lat), float(crest_lon))
    return 4000.0 - 3700.0 * np.exp(-((np.asarray(east) / RIDGE_WIDTH_KM) ** 2))


def write_ridge_grid(path: Path, info: FloatInfo, cell_arcmin: float = 2.0) -> Path:
    """The ridge as a GEBCO-like NetCDF grid: `elevation` (m, positive up) on lat/lon."""
    import xarray as xr

    step = cell_arcmin / 60.0
    lat = np.arange(info.launch_lat - 8.0, info.launch_lat + 8.0, step)
    lon = np.arange(info.launch_lon - 12.0, info.launch_lon + 12.0, step)
    lon2, lat2 = np.meshgrid(lon, lat)
    elevation = -ridge_depth_m(lat2, lon2, info)
    ds = xr.Dataset(
        {"elevation": (("lat", "lon"), elevation.astype(np.float32), {"units": "m", "positive": "up"})},
        coords={
            "lat": ("lat", lat, {"units": "degrees_north", "standard_name": "latitude"}),
            "lon": ("lon", lon, {"units": "degrees_east", "standard_name": "longitude"}),
        },
    )
    ds.to_netcdf(path)
    return path


def ridge_truth(info: FloatInfo, days: int, rng: np.random.Generator) -> pd.DataFrame:
    """Daily truth: the OU drift, each step redrawn while it would end too shallow."""
    model = IntegratedOU(EDDY_SD_KM_PER_DAY, EDDY_DAYS, CURRENT_KM_PER_DAY)
    state = Particles(np.array([info.launch_lat]), np.array([info.launch_lon]), np.array([CURRENT_KM_PER_DAY]))
    lat, lon = [info.launch_lat], [info.launch_lon]
    for _ in range(days):
        for _attempt in range(200):
            moved = model.step(state, 1.0, rng.standard_normal((4, 1)))
            if ridge_depth_m(moved.lat, moved.lon, info)[0] > FLOAT_DEPTH_M + CLEARANCE_M:
                break
        else:  # hemmed in: stay, with the velocity reversed
            moved = Particles(state.lat, state.lon, -np.asarray(state.velocity_km_per_day))
        state = moved
        lat.append(float(state.lat[0]))
        lon.append(float(state.lon[0]))
    times = info.launch_time + np.arange(days + 1) * np.timedelta64(86400, "s").astype("timedelta64[ns]")
    return pd.DataFrame({"time": times, "lat": lat, "lon": lon})


def _scenario(seed: int, days: int):
    beacons, floats = synthetic_scenario(days=days, rng=1)
    info = replace(floats[0], float_id=f"ridge{seed}", depth_m=FLOAT_DEPTH_M)
    rng = np.random.default_rng([seed, 12])
    truth = ridge_truth(info, days, rng)
    end = truth.iloc[-1]
    info = replace(info, end_time=truth["time"].to_numpy()[-1], end_lat=float(end["lat"]), end_lon=float(end["lon"]))
    config = load_config()
    record, _ = simulate_arrivals(beacons, info, config.model, truth, rng, days=days)
    day = (np.array([w.time for w in record.windows]) - info.launch_time) / np.timedelta64(1, "D")
    windows = []
    for w, d in zip(record.windows, day, strict=True):
        if GAP_DAYS[0] <= d < GAP_DAYS[1]:
            continue
        quiet = GAP_DAYS[1] <= d < GAP_DAYS[2]
        windows.append(Window(w.time, np.zeros(0), ()) if quiet else w)
    record = ArrivalRecord(record.float_id, record.path, tuple(windows))
    return beacons, info, truth, record


def track_pair(task: tuple[int, Sizes]) -> dict[str, Any]:
    """Track one simulated float with and without the bathymetry constraint."""
    from rafostrack.problem import FloatProblem
    from rafostrack.run.method import track_record

    seed, sz = task
    beacons, info, truth, record = _scenario(seed, sz.days)
    out: dict[str, Any] = {"truth": truth}
    with tempfile.TemporaryDirectory() as tmp:
        grid = write_ridge_grid(Path(tmp) / "ridge.nc", info)
        for name, context in (("without", {}), ("with", {"bathymetry": str(grid)})):
            config = load_config(
                overrides={
                    # No calibration (the two runs differ by the context alone): the drift
                    # model is the scenario's own, as calibration would learn it.
                    "calibrate": {"enabled": False},
                    # FFBSm for both: a context run cannot join a backward filter (its move
                    # factors are not reversed; `Tracker._joins_two_filters`).
                    "smoother": {"two_filter": False},
                    "filter": {"particles": sz.particles, "seed": seed},
                    "motion": {"mean_current_east_km_per_day": CURRENT_KM_PER_DAY[0],
                               "mean_current_north_km_per_day": CURRENT_KM_PER_DAY[1],
                               "velocity_sd_km_per_day": EDDY_SD_KM_PER_DAY,
                               "decorrelation_days": EDDY_DAYS},
                    **({"context": context} if context else {}),
                }
            )  # fmt: skip
            output = track_record(FloatProblem(beacons, info, config), record)
            track = output.track
            at = pd.merge_asof(track[["time", "lat", "lon"]].sort_values("time"), truth, on="time",
                               suffixes=("", "_true"), direction="nearest")  # fmt: skip
            east, north = local_offsets_km(at["lat"], at["lon"], at["lat_true"], at["lon_true"])
            depth = ridge_depth_m(track["lat"].to_numpy(), track["lon"].to_numpy(), info)
            out[name] = {"track": track, "err_km": np.hypot(east, north), "depth_m": depth}
    return out


def _rmse(err: NDArray) -> float:
    return float(np.sqrt(np.mean(np.asarray(err) ** 2)))


@experiment(FULL, QUICK)
def run(outdir: Path, sz: Sizes, *, seed: int = 0, workers: int = 2) -> dict[str, Any]:
    """Write floats_ridge.png and its CSV; return the summary."""
    runs = pmap(track_pair, [(seed + k, sz) for k in range(sz.repeats)], workers)
    table = pd.DataFrame([row for k, r in enumerate(runs) for row in _repeat_rows(k, r)])
    files = ["floats_ridge.png", "floats_ridge.csv"]
    save_csv(table, outdir / files[1])
    wide = table.pivot(index="repeat", columns="context")
    summary_rows = {name: _context_summary(table[table["context"] == name]) for name in ("without", "with")}
    diff = wide["rmse_km"]["with"] - wide["rmse_km"]["without"]
    _draw(outdir / files[0], runs[0], seed, sz)
    return {
        "name": "floats_ridge",
        "files": files,
        "seed": seed,
        "repeats": sz.repeats,
        "days": sz.days,
        "particles": sz.particles,
        "float_depth_m": FLOAT_DEPTH_M,
        "gap_days": list(GAP_DAYS),
        "table": summary_rows,
        "rmse_diff_km": mean_se(diff),
        "wins": int((diff < 0).sum()),
    }


def _repeat_rows(k: int, r: dict[str, Any]) -> list[dict[str, Any]]:
    """Repeat `k`'s two runs (`track_pair`), one row each: RMSE overall and over the gap and
    the 5 days after it, and the positions where the sea floor is shallower than the float
    (and forbidden: by more than FORBIDDEN_MARGIN_M)."""
    day = {name: (r[name]["track"]["time"].to_numpy() - r["truth"]["time"].to_numpy()[0]) / np.timedelta64(1, "D")
           for name in ("without", "with")}  # fmt: skip
    rows = []
    for name in ("without", "with"):
        quiet = (day[name] >= GAP_DAYS[0]) & (day[name] < GAP_DAYS[2] + 5)
        rows.append({
            "repeat": k, "context": name, "rmse_km": _rmse(r[name]["err_km"]),
            "rmse_gap_km": _rmse(r[name]["err_km"][quiet]),
            "shallower_positions": int(np.sum(r[name]["depth_m"] < FLOAT_DEPTH_M)),
            "forbidden_positions": int(np.sum(r[name]["depth_m"] < FLOAT_DEPTH_M - FORBIDDEN_MARGIN_M)),
            "positions": len(r[name]["err_km"]),
        })  # fmt: skip
    return rows


def _context_summary(part: pd.DataFrame) -> dict[str, Any]:
    """One context setting's rows over the repeats: mean ± SE RMSEs, summed position counts."""
    return {
        "rmse_km": mean_se(part["rmse_km"]),
        "rmse_gap_km": mean_se(part["rmse_gap_km"]),
        "shallower_positions": int(part["shallower_positions"].sum()),
        "forbidden_positions": int(part["forbidden_positions"].sum()),
        "positions": int(part["positions"].sum()),
    }


def _draw(path: Path, first: dict[str, Any], seed: int, sz: Sizes) -> None:
    """The figure of the first repeat: the tracks over the context layer (the ridge's
    forbidden ground), and the smoothed error against the day, the gap shaded."""
    from rafostrack.context.floats import FloatContext, build_context, mission_region
    from rafostrack.plots.context_layer import draw_context

    beacons, info, truth, _ = _scenario(seed, sz.days)
    with tempfile.TemporaryDirectory() as tmp:
        grid_path = write_ridge_grid(Path(tmp) / "ridge.nc", info)
        cfg = load_config(overrides={"context": {"bathymetry": str(grid_path)}}).context
        context: FloatContext = build_context(cfg, mission_region(info, beacons, cfg.margin_deg), FLOAT_DEPTH_M)
    with figure(13.0, 5.4) as fig:
        ax, ax_err = fig.subplots(1, 2, width_ratios=(1, 1.3))
        ax.plot(truth["lon"], truth["lat"], "-", color="k", lw=1.4, label="truth")
        colors = {"without": "tab:orange", "with": "tab:green"}
        for name in ("without", "with"):
            t = first[name]["track"]
            ax.plot(t["lon"], t["lat"], ".-", color=colors[name], ms=2.5, lw=0.8, label=f"smoothed, {name} context")
        lat0, lat1 = ax.get_ylim()
        lon0, lon1 = ax.get_xlim()
        draw_context(ax, lat0, lat1, lon0, lon1, context=context)
        ax.set_aspect(1.0 / np.cos(np.radians(info.launch_lat)), adjustable="datalim")
        ax.set_title("repetition 1 (dashed blue: the float's depth, 1000 m; red: CF < 0.5)", fontsize=8)
        ax.legend(fontsize=7)
        for name in ("without", "with"):
            t = first[name]["track"]
            d = (t["time"].to_numpy() - truth["time"].to_numpy()[0]) / np.timedelta64(1, "D")
            ax_err.plot(d, first[name]["err_km"], color=colors[name], label=f"{name} context")
        ax_err.axvspan(GAP_DAYS[0], GAP_DAYS[1], color="0.85", label="no windows (one motion step)")
        ax_err.axvspan(GAP_DAYS[1], GAP_DAYS[2], color="0.93", label="empty windows")
        ax_err.set_xlabel("day")
        ax_err.set_ylabel("smoothed position error (km)")
        ax_err.legend(fontsize=7)
        ax_err.grid(True, lw=0.4, alpha=0.5)
        fig.suptitle("A float along a ridge, with a gap: rafostrack with and without the bathymetry constraint")
        save_png(fig, path)
