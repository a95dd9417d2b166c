"""What the paper-figure experiments share: the paper's planar setting mapped onto rafostrack,
target trajectories, a seeded runner, parallel map, and figure/CSV/JSON writers.

The paper's simulations (section 3.1) live in a unit 2-D plane where an arrival time is a
distance over a speed: 10 beacons, the first 4 signals stored, Pd = 0.7, TOA sd 0.02 (in
units of distance), clutter Poisson(lambda) per window, uniform over the window. rafostrack
works on the WGS84 ellipsoid with a sound speed, so `PaperSetting` maps the plane onto a
geographic box: one paper unit is `unit_km` km east/north of the box centre (a local
equirectangular projection), arrival times are WGS84 ranges over `sound_speed_m_s`, and the
TOA sd is 0.02 units of travel time. Simulation is `rafostrack.simulate.simulate_arrivals`
and tracking `rafostrack.tracker.track_record`: the package's own model, not a copy.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import multiprocessing
import os
import time
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.figure import Figure
from numpy.typing import NDArray

from .. import plots
from ..config import Config, load_config, method_overrides, with_overrides
from ..domain import ArrivalRecord, BeaconTable, FloatInfo
from ..evaluate import position_errors_km
from ..geodesy import displace, local_offsets_km
from ..io.atomic import write_text_atomic
from ..io.writers import write_json
from ..plots import save_png
from ..simulate import simulate_arrivals
from ..tracker import TrackOutput, track_record
from ..workers import single_threaded_math

T0 = np.datetime64("2010-01-01T00:00:00", "ns")
ONE_DAY = np.timedelta64(86400, "s").astype("timedelta64[ns]")
NaT = np.datetime64("NaT", "ns")
DPI = 110
REPO = Path(__file__).resolve().parents[2]
SAMPLES = REPO / "data" / "samples"
# Two workers: the figures' budget is stated for a 2-core machine.
DEFAULT_WORKERS = max(1, min(2, os.cpu_count() or 1))
CLUTTER_LEVELS = (0.5, 1.0, 2.0, 4.0, 8.0)
LOST_UNITS = 0.1  # a window's position error above this (50 km) counts as the target lost


# --------------------------------------------------------------------------------------
# The paper's plane on the ellipsoid


@dataclass(frozen=True)
class PaperSetting:
    """The paper's simulation setting (section 3.1) on a geographic box near 58 S."""

    unit_km: float = 500.0  # one paper unit of distance
    centre_lat: float = -58.0  # the plane's point (0.5, 0.5)
    centre_lon: float = -90.0
    sound_speed_m_s: float = 1480.0
    sigma_units: float = 0.02  # TOA sd, in units of distance travelled
    p_detect: float = 0.7
    n_beacons: int = 10
    max_signals: int = 4
    window_units: float = 1.5  # > sqrt(2): every arrival from inside the box fits
    beacon_seed: int = 2015  # the beacons' fixed random positions in the unit box
    launch_sd_km: float = 1.0  # the known initial position X_0 (tracker's launch prior)

    @property
    def unit_s(self) -> float:
        """Travel time (s) of one paper unit."""
        return self.unit_km * 1e3 / self.sound_speed_m_s

    @property
    def toa_sigma_s(self) -> float:
        return self.sigma_units * self.unit_s

    @property
    def window_s(self) -> float:
        return round(self.window_units * self.unit_s, 2)

    def to_geo(self, x: NDArray, y: NDArray) -> tuple[NDArray, NDArray]:
        """Plane (units) to (lat, lon): (0.5, 0.5) is the box centre."""
        x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        east, north = (x - 0.5) * self.unit_km, (y - 0.5) * self.unit_km
        return displace(np.full(x.shape, self.centre_lat), np.full(x.shape, self.centre_lon), east, north)

    def to_plane(self, lat: NDArray, lon: NDArray) -> tuple[NDArray, NDArray]:
        """(lat, lon) to plane units (the exact inverse of `to_geo`)."""
        east, north = local_offsets_km(np.asarray(lat), np.asarray(lon), self.centre_lat, self.centre_lon)
        return 0.5 + np.asarray(east) / self.unit_km, 0.5 + np.asarray(north) / self.unit_km

    def beacon_xy(self) -> NDArray[np.float64]:
        """(n_beacons, 2) fixed random beacon positions, uniform in the unit box."""
        return np.random.default_rng(self.beacon_seed).uniform(0.0, 1.0, (self.n_beacons, 2))

    def beacons(self) -> BeaconTable:
        """Always active, transmitting at the window's opening (offset 0), no clock drift."""
        xy = self.beacon_xy()
        lat, lon = self.to_geo(xy[:, 0], xy[:, 1])
        n = self.n_beacons
        return BeaconTable(
            beacon_id=np.array([f"B{i + 1}" for i in range(n)], dtype=object),
            lat=np.asarray(lat, dtype=float),
            lon=np.asarray(lon, dtype=float),
            offset_s=np.zeros(n),
            drift_s_per_day=np.zeros(n),
            start=np.full(n, NaT),
            end=np.full(n, NaT),
        )

    def float_info(self, float_id: str, x0: float, y0: float) -> FloatInfo:
        """A target launched at (x0, y0) at T0, no end fix (the paper has none), no clock error."""
        lat, lon = self.to_geo(np.array([x0]), np.array([y0]))
        return FloatInfo(
            float_id=float_id,
            launch_time=T0,
            launch_lat=float(lat[0]),
            launch_lon=float(lon[0]),
            end_time=NaT,
            end_lat=math.nan,
            end_lon=math.nan,
            clock_offset_start_s=0.0,
            clock_offset_end_s=0.0,
            window_s=self.window_s,
            max_signals=self.max_signals,
        )

    def config(
        self,
        *,
        clutter_rate: float,
        diffusion_km_per_day: float,
        method: str = "exact",
        particles: int = 1000,
        seed: int = 0,
        smooth: bool = True,
    ) -> Config:
        """The tracker's configuration: the model matches the simulation's."""
        return with_overrides(
            load_config(),
            model={
                "sound_speed_m_s": self.sound_speed_m_s,
                "toa_sigma_s": self.toa_sigma_s,
                "p_detect": self.p_detect,
                "clutter_rate": float(clutter_rate),
                "multipath_fraction": 0.0,
                "detection_range_km": 0.0,
                "window_s": self.window_s,
                "max_signals": self.max_signals,
            },
            motion={"diffusion_km_per_day": float(diffusion_km_per_day)},
            fixes={"launch_sd_km": self.launch_sd_km, "use_end_fix": False},
            filter={**method_overrides(method), "particles": int(particles), "seed": int(seed)},
            smoother={"enabled": bool(smooth)},
        )

    def describe(self) -> str:
        """The mapping, for REPORT.md."""
        return (
            f"one paper unit = {self.unit_km:g} km (a local east/north plane centred at "
            f"{abs(self.centre_lat):g}°S {abs(self.centre_lon):g}°W); sound speed {self.sound_speed_m_s:g} m/s, "
            f"so one unit of travel takes {self.unit_s:.1f} s; TOA sd 0.02 units = {self.toa_sigma_s:.2f} s "
            f"({self.sigma_units * self.unit_km:g} km); {self.n_beacons} beacons at fixed uniform random positions "
            f"in the unit box (seed {self.beacon_seed}), always on, offset 0; window {self.window_s:g} s "
            f"({self.window_units:g} units, longer than the box diagonal); Pd {self.p_detect:g}; first "
            f"{self.max_signals} signals stored; clutter Poisson(lambda) per window, uniform over the window; "
            f"arrival time = WGS84 range / sound speed (within ~6% of the plane distance at the box's edges; "
            f"simulator and tracker share it); launch position known to {self.launch_sd_km:g} km, no end fix"
        )


# --------------------------------------------------------------------------------------
# Trajectories (daily positions in plane units, launch first)


def line_xy(days: int, start: tuple[float, float] = (0.15, 0.2), end: tuple[float, float] = (0.85, 0.75)) -> NDArray:
    """A straight line at constant speed (paper Figs. 4a and 6a), shape (days + 1, 2)."""
    f = np.linspace(0.0, 1.0, days + 1)[:, None]
    return (1.0 - f) * np.asarray(start) + f * np.asarray(end)


def spiral_xy(days: int, r_out: float = 0.42, r_in: float = 0.08, turns: float = 2.0) -> NDArray:
    """An inward Archimedean spiral about the box centre at constant speed (paper Fig. 5a)."""
    theta = np.linspace(0.0, 2.0 * np.pi * turns, 20001)
    r = r_out - (r_out - r_in) * theta / theta[-1]
    dense = np.column_stack([0.5 + r * np.cos(theta), 0.5 + r * np.sin(theta)])
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(dense, axis=0).T))])
    s = np.linspace(0.0, arc[-1], days + 1)
    return np.column_stack([np.interp(s, arc, dense[:, 0]), np.interp(s, arc, dense[:, 1])])


@dataclass(frozen=True)
class Scenario:
    """A target with an explicit daily truth track in the paper setting."""

    name: str
    setting: PaperSetting
    xy: NDArray[np.float64]  # (days + 1, 2) plane positions, launch first
    beacons: BeaconTable
    info: FloatInfo
    truth: pd.DataFrame  # time, lat, lon (launch and every window)

    @property
    def days(self) -> int:
        return len(self.xy) - 1

    @property
    def step_km(self) -> float:
        """Mean daily displacement of the truth (km)."""
        return float(np.mean(np.hypot(*np.diff(self.xy, axis=0).T)) * self.setting.unit_km)

    @property
    def diffusion_km_per_day(self) -> float:
        """The tracker's random-walk sd per axis per day: the truth's daily step, so one day's
        true displacement is about one random-walk sd along any axis."""
        return round(self.step_km, 2)

    def simulate(self, config: Config, rng: np.random.Generator) -> ArrivalRecord:
        """Arrivals along the truth by the package's generative model."""
        record, _ = simulate_arrivals(self.beacons, self.info, config.model, self.truth, rng, days=self.days)
        return record

    def config(self, clutter_rate: float, **kwargs: Any) -> Config:
        return self.setting.config(clutter_rate=clutter_rate, diffusion_km_per_day=self.diffusion_km_per_day, **kwargs)


def make_scenario(shape: str, days: int, setting: PaperSetting | None = None) -> Scenario:
    """`shape` "line" (paper Fig. 4 / 6) or "spiral" (Fig. 5)."""
    setting = setting or PaperSetting()
    if shape == "line":
        xy = line_xy(days)
    elif shape == "spiral":
        xy = spiral_xy(days)
    else:
        raise ValueError(f"unknown trajectory {shape!r}: expected line or spiral")
    lat, lon = setting.to_geo(xy[:, 0], xy[:, 1])
    truth = pd.DataFrame({"time": T0 + ONE_DAY * np.arange(days + 1), "lat": lat, "lon": lon})
    info = setting.float_info(shape, xy[0, 0], xy[0, 1])
    return Scenario(shape, setting, xy, setting.beacons(), info, truth)


def data_rng(seed: int, *keys: float) -> np.random.Generator:
    """The simulation generator of one (seed, case...) run, independent of run order."""
    return np.random.default_rng([int(seed), *(round(k * 1000) for k in keys)])


# --------------------------------------------------------------------------------------
# Running and scoring


@dataclass(frozen=True)
class MethodRun:
    """Scores of one method on one simulated record (filtered and smoothed)."""

    method: str
    output: TrackOutput
    sq_err_filtered: NDArray[np.float64]  # per window, plane units^2
    sq_err_smoothed: NDArray[np.float64]
    seconds: float


def run_method(
    scenario: Scenario, record: ArrivalRecord, config: Config, method: str, *, smooth: bool = True
) -> MethodRun:
    """Track `record` with `method` (filtered, and smoothed when `smooth`) and score both
    against the scenario's truth in squared plane units."""
    cfg = with_overrides(config, filter=method_overrides(method), smoother={"enabled": smooth})
    out = track_record(scenario.beacons, scenario.info, cfg, record, also_filtered=True)
    unit2 = scenario.setting.unit_km**2
    err_f = position_errors_km(out.filtered.track, scenario.truth) ** 2 / unit2
    err_s = position_errors_km(out.estimate.track, scenario.truth) ** 2 / unit2 if smooth else err_f
    return MethodRun(method, out, err_f, err_s, out.filter_s + out.smoother_s)


def pmap(fn: Callable[[Any], Any], tasks: Sequence[Any], workers: int = DEFAULT_WORKERS) -> list[Any]:
    """`[fn(t) for t in tasks]`, in `workers` processes when > 1 (order kept). Every task
    carries its own seed, so results do not depend on scheduling. Workers are spawned with
    single-threaded BLAS: two processes each running a multi-threaded BLAS on two cores are
    slower than one."""
    if workers <= 1 or len(tasks) <= 1:
        return [fn(t) for t in tasks]
    with (
        single_threaded_math(),
        ProcessPoolExecutor(
            max_workers=min(workers, len(tasks)), mp_context=multiprocessing.get_context("spawn")
        ) as pool,
    ):
        return list(pool.map(fn, tasks))


def mean_se(values: Iterable[float]) -> tuple[float, float]:
    """Mean and its standard error (sample sd / sqrt(n); NaN se for n < 2)."""
    v = np.asarray(list(values), dtype=float)
    if len(v) == 0:
        return math.nan, math.nan
    se = float(v.std(ddof=1) / np.sqrt(len(v))) if len(v) > 1 else math.nan
    return float(v.mean()), se


def true_signal_counts(record: ArrivalRecord) -> NDArray[np.int64]:
    """Stored TOAs per window that came from a beacon (by the record's known labels)."""
    return np.array([sum(b is not None for b in (w.beacon_id or ())) for w in record.windows], dtype=np.int64)


def day_text(t: np.datetime64) -> str:
    return str(np.datetime_as_string(np.datetime64(t, "D")))


def span_text(spans: Sequence[tuple[np.datetime64, np.datetime64]], limit: int = 12) -> str:
    """'2009-03-01..2009-03-04, 2009-05-02' (a single day once); 'none' when empty."""
    if not spans:
        return "none"
    parts = [day_text(a) if a == b else f"{day_text(a)}..{day_text(b)}" for a, b in spans[:limit]]
    more = f" and {len(spans) - limit} more" if len(spans) > limit else ""
    return ", ".join(parts) + more


# --------------------------------------------------------------------------------------
# Output


def figure(width: float, height: float) -> contextlib.AbstractContextManager[Figure]:
    """A fresh Agg-backed figure of the experiments' size and resolution."""
    return plots.figure(width, height, dpi=DPI)


def save_csv(frame: pd.DataFrame, path: Path) -> Path:
    write_text_atomic(path, frame.to_csv(index=False, float_format="%.6g", lineterminator="\n"))
    return Path(path)


def save_summary(summary: dict[str, Any], outdir: Path) -> dict[str, Any]:
    """Write `<name>.json` (the summary REPORT.md is built from) and return the summary."""
    write_json(Path(outdir) / f"{summary['name']}.json", summary)
    return summary


def cli(run: Callable[..., dict[str, Any]], doc: str | None, argv: Sequence[str] | None = None) -> dict[str, Any]:
    """`python -m rafostrack.experiments.<module> OUTDIR [--quick] [--seed N] [--workers N]`."""
    parser = argparse.ArgumentParser(description=(doc or "").strip().splitlines()[0])
    parser.add_argument("outdir", type=Path)
    parser.add_argument("--quick", action="store_true", help="small sizes (CI)")
    parser.add_argument("--seed", type=int, default=None)
    parser.add_argument("--workers", type=int, default=DEFAULT_WORKERS)
    args = parser.parse_args(argv)
    kwargs: dict[str, Any] = {"quick": args.quick, "workers": args.workers}
    if args.seed is not None:
        kwargs["seed"] = args.seed
    summary = run(args.outdir, **kwargs)
    print(f"{summary['name']}: wrote {', '.join(summary['files'])} to {args.outdir}")
    return summary


# --------------------------------------------------------------------------------------
# Figs. 4 and 5: one target, its track and its labelled arrivals


@dataclass(frozen=True)
class TrajectorySizes:
    days: int
    particles: int
    clutter_rate: float = 4.0  # the paper's Poisson(4), Pc = 0.8


def resolve_sizes(default: Any, overrides: dict[str, Any] | None) -> Any:
    return default if not overrides else type(default)(**{**default.__dict__, **overrides})


def method_task(task: tuple[Scenario, ArrivalRecord, Config, str]) -> MethodRun:
    """`run_method(*task)`, for `pmap`."""
    return run_method(*task)


def run_trajectory(
    name: str,
    shape: str,
    title: str,
    outdir: Path,
    *,
    full: TrajectorySizes,
    quick_sizes: TrajectorySizes,
    quick: bool,
    seed: int,
    workers: int,
    sizes: dict[str, Any] | None,
) -> dict[str, Any]:
    """Simulate one target on `shape` at clutter Poisson(4), track it with the ranked model
    (exact engine; filtered = the paper's estimate, smoothed = ours), the unranked baseline
    and the labelled filter, and draw the track and the labelled arrival times."""
    from ..evaluate import association_accuracy

    started = time.perf_counter()
    outdir = Path(outdir)
    sz = resolve_sizes(quick_sizes if quick else full, sizes)
    scenario = make_scenario(shape, sz.days)
    config = scenario.config(sz.clutter_rate, particles=sz.particles, seed=seed)
    record = scenario.simulate(config, data_rng(seed, sz.clutter_rate))
    methods = ("exact", "unranked", "labeled")
    runs = dict(zip(methods, pmap(method_task, [(scenario, record, config, m) for m in methods], workers), strict=True))
    ours = runs["exact"]
    setting = scenario.setting
    n_true = true_signal_counts(record)
    n_stored = np.array([w.n_signals for w in record.windows])

    track_f, track_s = ours.output.filtered.track, ours.output.estimate.track
    xf, yf = setting.to_plane(track_f["lat"], track_f["lon"])
    xs, ys = setting.to_plane(track_s["lat"], track_s["lon"])
    xb, yb = setting.to_plane(
        runs["unranked"].output.filtered.track["lat"], runs["unranked"].output.filtered.track["lon"]
    )
    truth_xy = scenario.xy[1:]
    table = pd.DataFrame(
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
            "err_unranked_units": np.sqrt(runs["unranked"].sq_err_filtered),
            "err_labeled_units": np.sqrt(runs["labeled"].sq_err_filtered),
            "n_stored": n_stored,
            "n_true": n_true,
        }
    )
    truth_labels = [b for w in record.windows for b in (w.beacon_id or ())]
    labels = ours.output.estimate.labels
    arrivals = pd.DataFrame(
        {
            "day": [(w.time - T0) // ONE_DAY for w in record.windows for _ in range(w.n_signals)],
            "rank": labels["rank"].to_numpy(),
            "toa_s": labels["toa_s"].to_numpy(),
            "toa_units": labels["toa_s"].to_numpy() / setting.unit_s,
            "true_beacon": [b or "" for b in truth_labels],
            "label_smoothed": [b if isinstance(b, str) else "" for b in labels["beacon_id"]],
            "prob_smoothed": labels["prob"].to_numpy(),
            "label_filtered": [b if isinstance(b, str) else "" for b in ours.output.filtered.labels["beacon_id"]],
        }
    )
    files = [f"{name}.png", f"{name}_track.csv", f"{name}_arrivals.csv"]
    save_csv(table, outdir / files[1])
    save_csv(arrivals, outdir / files[2])
    wrong = arrivals["true_beacon"] != arrivals["label_smoothed"]
    label_errors = {
        "beacon_swapped": int((wrong & (arrivals["true_beacon"] != "") & (arrivals["label_smoothed"] != "")).sum()),
        "clutter_as_beacon": int((wrong & (arrivals["true_beacon"] == "")).sum()),
        "beacon_as_clutter": int((wrong & (arrivals["label_smoothed"] == "")).sum()),
        "stored": len(arrivals),
    }
    acc_s = association_accuracy(labels, record)
    acc_f = association_accuracy(ours.output.filtered.labels, record)
    _draw_trajectory(outdir / files[0], scenario, table, arrivals, title, sz, acc_s)

    def units_rmse(sq: NDArray) -> float:
        return float(np.sqrt(sq.mean()))

    summary = {
        "name": name,
        "title": title,
        "files": files,
        "quick": quick,
        "seed": seed,
        "days": scenario.days,
        "particles": sz.particles,
        "clutter_rate": sz.clutter_rate,
        "step_km": round(scenario.step_km, 2),
        "diffusion_km_per_day": scenario.diffusion_km_per_day,
        "mapping": setting.describe(),
        "stored_per_window": float(n_stored.mean()),
        "clutter_fraction": float(1.0 - n_true.sum() / max(n_stored.sum(), 1)),
        "frac_windows_lt3_true": float(np.mean(n_true < 3)),
        "mse_units2": {
            "exact_filtered": float(ours.sq_err_filtered.mean()),
            "exact_smoothed": float(ours.sq_err_smoothed.mean()),
            "unranked_filtered": float(runs["unranked"].sq_err_filtered.mean()),
            "unranked_smoothed": float(runs["unranked"].sq_err_smoothed.mean()),
            "labeled_filtered": float(runs["labeled"].sq_err_filtered.mean()),
            "labeled_smoothed": float(runs["labeled"].sq_err_smoothed.mean()),
        },
        "rmse_km": {
            "exact_filtered": units_rmse(ours.sq_err_filtered) * setting.unit_km,
            "exact_smoothed": units_rmse(ours.sq_err_smoothed) * setting.unit_km,
            "unranked_filtered": units_rmse(runs["unranked"].sq_err_filtered) * setting.unit_km,
            "labeled_filtered": units_rmse(runs["labeled"].sq_err_filtered) * setting.unit_km,
        },
        "lost_frac": {
            key: float(np.mean(sq > LOST_UNITS**2))
            for key, sq in (
                ("exact_filtered", ours.sq_err_filtered),
                ("exact_smoothed", ours.sq_err_smoothed),
                ("unranked_filtered", runs["unranked"].sq_err_filtered),
            )
        },
        "ambiguous_windows": {
            "exact_filtered": int(track_f["ambiguous"].sum()),
            "exact_smoothed": int(track_s["ambiguous"].sum()),
        },
        "max_err_km_smoothed": float(np.sqrt(ours.sq_err_smoothed.max()) * setting.unit_km),
        "label_accuracy": {"filtered": acc_f, "smoothed": acc_s},
        "label_errors_smoothed": label_errors,
        "seconds": round(time.perf_counter() - started, 1),
    }
    return save_summary(summary, outdir)


def _draw_trajectory(
    path: Path, scenario: Scenario, table: pd.DataFrame, arrivals: pd.DataFrame, title: str, sz: Any, acc: float
) -> None:
    from matplotlib.lines import Line2D

    from ..plots import beacon_colors

    setting = scenario.setting
    bxy = setting.beacon_xy()
    ids = [str(b) for b in scenario.beacons.beacon_id]
    colors = beacon_colors(ids)
    with figure(13.0, 5.6) as fig:
        ax_map, ax_toa = fig.subplots(1, 2, width_ratios=[1.0, 1.35])
        for k, b in enumerate(ids):
            ax_map.plot(*bxy[k], "^", color=colors[b], ms=9, mec="k", mew=0.6, zorder=5)
            ax_map.annotate(b, bxy[k], xytext=(4, 4), textcoords="offset points", fontsize=8)
        ax_map.plot(scenario.xy[:, 0], scenario.xy[:, 1], "-", color="k", lw=2.2, label="truth", zorder=2)
        ax_map.plot(*scenario.xy[0], "o", color="k", ms=6, zorder=6)
        ax_map.plot(
            table["x_unranked"], table["y_unranked"], ":", color="0.5", lw=1.2, label="unranked baseline (filtered)"
        )
        ax_map.plot(
            table["x_filtered"],
            table["y_filtered"],
            "-",
            color="tab:orange",
            lw=1.2,
            label="ranked, exact, filtered (paper)",
        )
        ax_map.plot(
            table["x_smoothed"],
            table["y_smoothed"],
            "-",
            color="tab:blue",
            lw=1.5,
            label="ranked, exact, smoothed (ours)",
        )
        est = table[["x_filtered", "y_filtered", "x_smoothed", "y_smoothed", "x_unranked", "y_unranked"]].to_numpy()
        lo = max(min(-0.05, float(np.nanmin(est)) - 0.02), -0.5)
        hi = min(max(1.05, float(np.nanmax(est)) + 0.02), 1.5)
        ax_map.set_xlim(lo, hi)
        ax_map.set_ylim(lo, hi)
        ax_map.set_aspect("equal")
        ax_map.set_xlabel("x (paper units)")
        ax_map.set_ylabel("y (paper units)")
        ax_map.grid(True, lw=0.4, alpha=0.5)
        ax_map.legend(loc="lower right", fontsize=8, framealpha=0.9)
        ax_map.set_title(f"(a) {title}: true vs estimated track", fontsize=10)

        days = np.arange(0, scenario.days + 1)
        pred = np.hypot(scenario.xy[:, None, 0] - bxy[None, :, 0], scenario.xy[:, None, 1] - bxy[None, :, 1])
        for k, b in enumerate(ids):
            ax_toa.plot(days, pred[:, k], "-", color=colors[b], lw=0.8, alpha=0.6, zorder=1)
        true_b = arrivals["true_beacon"].to_numpy()
        est_b = arrivals["label_smoothed"].to_numpy()
        x, t = arrivals["day"].to_numpy(), arrivals["toa_units"].to_numpy()
        clutter = true_b == ""
        ax_toa.scatter(x[clutter], t[clutter], marker="x", s=18, c="0.35", linewidths=0.9, zorder=3)
        for b in ids:
            sel = true_b == b
            if sel.any():
                ax_toa.scatter(x[sel], t[sel], s=18, color=colors[b], edgecolors="none", zorder=4)
        wrong = true_b != est_b
        ax_toa.scatter(x[wrong], t[wrong], s=70, facecolors="none", edgecolors="red", linewidths=1.1, zorder=5)
        ax_toa.set_ylim(0.0, setting.window_units)
        ax_toa.set_xlim(0, scenario.days + 1)
        ax_toa.set_xlabel("time step (day)")
        ax_toa.set_ylabel("arrival time (paper units = distance)")
        ax_toa.grid(True, lw=0.4, alpha=0.5)
        handles = [
            Line2D([], [], color="0.3", lw=0.8, label="true arrival curve (colour = beacon)"),
            Line2D([], [], ls="none", marker="o", color="tab:blue", label="stored TOA, colour = true beacon"),
            Line2D([], [], ls="none", marker="x", color="0.35", label="stored clutter"),
            Line2D([], [], ls="none", marker="o", mfc="none", mec="red", ms=9, label="our smoothed label is wrong"),
        ]
        ax_toa.legend(handles=handles, loc="upper right", fontsize=8, framealpha=0.9)
        ax_toa.set_title(
            f"(b) stored arrival times (first {setting.max_signals}), clutter Poisson({sz.clutter_rate:g}), "
            f"Pd {setting.p_detect:g}; labels {acc:.1%} right",
            fontsize=10,
        )
        save_png(fig, path)
