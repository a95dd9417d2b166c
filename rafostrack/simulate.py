"""Simulate RAFOS missions (arrival files plus the true track) from the tracker's own model.

Generative model, per float (all randomness from one `numpy.random.Generator`, drawn in a
fixed order: floats in order; per float the drift, then the windows in time order):

Drift (the truth track). Positions at the launch time and every day after it, up to the
end time (plus the end time itself if the mission is not a whole number of days), or for
`days` days when the float has no end time. The east/north velocity (km/day) is
    v(t) = vbar + u(t),
vbar = the launch-to-end offset (local tangent plane at launch, `geodesy.local_offsets_km`)
over the duration (0 without an end fix), and u an Ornstein-Uhlenbeck process per axis with
stationary sd `eddy_speed_km_per_day` and timescale T = `eddy_timescale_days`, started from
its stationary law and updated exactly: u_{k+1} = a u_k + sd sqrt(1 - a^2) z_k,
a = exp(-dt_k / T), z_k ~ N(0, 1). Each step moves the float by v(t_k) dt_k with
`geodesy.displace`. When the float has an end fix, a bridge then adds a linear-in-time
correction: a constant extra velocity c, so the displacement correction is c (t - t_launch),
found by fixed-point iteration (c += miss / duration, re-integrating the same eddies) until
the track ends within 1 mm of the end fix; the last point is then set to the fix. (In the
tangent plane this is the textbook bridge; doing it with `displace` rather than in degrees
keeps eddy speeds in km/day unchanged when the correction moves the track in latitude.)

Windows. One per day at the launch's time of day, from the day after launch up to (not
beyond) the end time, and at most `days` of them. The float's position in a window is the
truth at the window time. In each window, for each beacon active then
(`BeaconTable.active_at`), using `model.window_beacons`, `beacon_ranges_m`,
`predicted_toa_s` and `detection_prob` (so simulator and tracker share one model,
including source drift and the float clock offset):
  * the signal is detected with probability Pd(range);
  * a detected signal arrives at mu + e, e ~ N(0, toa_sigma_s^2), plus, with probability
    `multipath_fraction`, an Exponential(mean `multipath_delay_s`) delay;
  * clutter: N ~ Poisson(`clutter_rate`) signals, uniform on [0, window_s].
Arrival times are quantised to `TOA_RESOLUTION_S` (0.01 s, the files' resolution; signals
that then coincide are one received signal, keeping the first label in beacon-table order,
clutter last: a ~1e-5 per window event). Of the received signals inside [0, window_s] the
float stores the earliest `max_signals`; each stored TOA keeps the beacon that produced it
(None = clutter). A window with nothing stored is kept (written as one row, empty toa_s).

Random draws per window, always in this order and whatever their use: uniform (detection),
normal (TOA error), uniform (multipath) and standard exponential (delay), one of each per
active beacon; then the clutter count and its times.

Scenarios: `dimes_scenario` (the real DIMES sources, deployment dates, launch/recovery
fixes and clock offsets, from `rafostrack/data/`) and `synthetic_scenario` (a small ring
array for fast tests and benchmarks). `write_mission` writes a mission directory that
`rafostrack track` reads, with the true labels as hand labels and the truth beside it.
"""

from __future__ import annotations

import csv
import io
import json
import math
import tomllib
from dataclasses import asdict, dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from .config import ModelConfig, load_config, merge_layer
from .domain import ArrivalRecord, BeaconTable, FloatInfo, Window
from .geodesy import displace, local_offsets_km, wrap_lon
from .io.atomic import write_text_atomic
from .model import beacon_ranges_m, detection_prob, predicted_toa_s, window_beacons

TOA_RESOLUTION_S = 0.01
_TOA_DECIMALS = 2
NaT = np.datetime64("NaT", "ns")
ONE_DAY = np.timedelta64(86400, "s").astype("timedelta64[ns]")
_BRIDGE_TOL_KM = 1e-6
_BRIDGE_MAX_ITER = 50


@dataclass(frozen=True)
class SimulatedFloat:
    """One simulated float: its info, stored arrivals (with true labels) and true track.

    `truth`: columns time (datetime64[ns]), lat, lon. `arrivals`: every signal received
    inside the window [0, window_s] (columns time = window time, toa_s, beacon_id with None
    for clutter, stored), before the float keeps the earliest `max_signals`.
    """

    info: FloatInfo
    record: ArrivalRecord
    truth: pd.DataFrame
    arrivals: pd.DataFrame = field(default_factory=pd.DataFrame)


@dataclass(frozen=True)
class SimulatedMission:
    beacons: BeaconTable
    floats: list[SimulatedFloat]
    model: ModelConfig
    eddy_speed_km_per_day: float = 4.0
    eddy_timescale_days: float = 10.0


# --------------------------------------------------------------------------------------
# The generator


def simulate_mission(
    beacons: BeaconTable,
    floats: list[FloatInfo],
    model: ModelConfig,
    rng: np.random.Generator,
    *,
    eddy_speed_km_per_day: float = 4.0,
    eddy_timescale_days: float = 10.0,
    days: int | None = None,
) -> SimulatedMission:
    """Simulate every float of `floats` (see the module docstring for the model)."""
    if eddy_speed_km_per_day < 0 or not eddy_timescale_days > 0:
        raise ValueError("eddy_speed_km_per_day must be >= 0 and eddy_timescale_days > 0")
    if days is not None and days < 0:
        raise ValueError(f"days must be >= 0, got {days}")
    out = []
    for info in floats:
        truth = simulate_drift(info, rng, eddy_speed_km_per_day, eddy_timescale_days, days)
        record, arrivals = simulate_arrivals(beacons, info, model, truth, rng, days=days)
        out.append(SimulatedFloat(info, record, truth, arrivals))
    return SimulatedMission(beacons, out, model, float(eddy_speed_km_per_day), float(eddy_timescale_days))


def _track_times(info: FloatInfo, days: int | None) -> NDArray[np.datetime64]:
    """Launch, then every day, then the end time (or launch + `days` without an end fix)."""
    launch = np.datetime64(info.launch_time, "ns")
    if not np.isnat(info.end_time):
        end = np.datetime64(info.end_time, "ns")
        n = int((end - launch) // ONE_DAY)
        times = launch + ONE_DAY * np.arange(n + 1)
        return times if times[-1] == end else np.append(times, end)
    if days is None:
        raise ValueError(f"float {info.float_id!r} has no end time: give `days` to simulate")
    return launch + ONE_DAY * np.arange(days + 1)


def simulate_drift(
    info: FloatInfo,
    rng: np.random.Generator,
    eddy_speed_km_per_day: float = 4.0,
    eddy_timescale_days: float = 10.0,
    days: int | None = None,
) -> pd.DataFrame:
    """The true track: mean velocity + OU eddies, bridged to the end fix (module docstring)."""
    times = _track_times(info, days)
    dt = np.diff(times) / ONE_DAY  # days
    duration = float((times[-1] - times[0]) / ONE_DAY)
    if info.has_end_fix and duration > 0:
        east, north = local_offsets_km(info.end_lat, info.end_lon, info.launch_lat, info.launch_lon)
        vbar = np.array([float(east), float(north)]) / duration
    else:
        vbar = np.zeros(2)
    sd, tau = eddy_speed_km_per_day, eddy_timescale_days
    u = sd * rng.standard_normal(2)
    z = rng.standard_normal((len(dt), 2))
    eddy = np.empty((len(dt), 2))
    for k, step in enumerate(dt):
        eddy[k] = u
        a = math.exp(-step / tau)
        u = a * u + sd * math.sqrt(1.0 - a * a) * z[k]
    lat0, lon0 = info.launch_lat, float(wrap_lon(info.launch_lon))
    lat, lon = _integrate(lat0, lon0, vbar + eddy, dt)
    if info.has_end_fix and duration > 0:
        # Bridge: a constant extra velocity c (a displacement growing linearly in time),
        # by fixed-point iteration until the integrated track ends at the end fix.
        c = np.zeros(2)
        for _ in range(_BRIDGE_MAX_ITER):
            miss = np.array(local_offsets_km(info.end_lat, info.end_lon, lat[-1], lon[-1]), dtype=float)
            if np.hypot(*miss) < _BRIDGE_TOL_KM:
                break
            c += miss / duration
            lat, lon = _integrate(lat0, lon0, vbar + c + eddy, dt)
        else:
            raise RuntimeError(f"float {info.float_id!r}: the drift bridge did not converge")
        lat[-1], lon[-1] = info.end_lat, float(wrap_lon(info.end_lon))  # exact, not to 1e-6 km
    return pd.DataFrame({"time": times.astype("datetime64[ns]"), "lat": lat, "lon": lon})


def _integrate(lat0: float, lon0: float, velocity: NDArray, dt: NDArray) -> tuple[NDArray, NDArray]:
    """Positions after each step of `velocity` (east, north km/day) for `dt` days."""
    lat = np.empty(len(dt) + 1)
    lon = np.empty(len(dt) + 1)
    lat[0], lon[0] = lat0, lon0
    for k, step in enumerate(dt):
        lat[k + 1], lon[k + 1] = displace(lat[k], lon[k], velocity[k, 0] * step, velocity[k, 1] * step)
    return lat, lon


def window_times(info: FloatInfo, days: int | None = None) -> NDArray[np.datetime64]:
    """Daily windows at the launch's time of day, from the day after launch to the end."""
    launch = np.datetime64(info.launch_time, "ns")
    n = days
    if not np.isnat(info.end_time):
        n_end = int((np.datetime64(info.end_time, "ns") - launch) // ONE_DAY)
        n = n_end if n is None else min(n, n_end)
    if n is None:
        raise ValueError(f"float {info.float_id!r} has no end time: give `days` to simulate")
    return launch + ONE_DAY * np.arange(1, n + 1)


def simulate_arrivals(
    beacons: BeaconTable,
    info: FloatInfo,
    model: ModelConfig,
    truth: pd.DataFrame,
    rng: np.random.Generator,
    *,
    days: int | None = None,
) -> tuple[ArrivalRecord, pd.DataFrame]:
    """Windows of stored TOAs (with true labels) along `truth`, and all received signals."""
    wtimes = window_times(info, days)
    truth_times = truth["time"].to_numpy(dtype="datetime64[ns]")
    pos = np.searchsorted(truth_times, wtimes)
    if len(wtimes) and (pos.max() >= len(truth_times) or np.any(truth_times[pos] != wtimes)):
        raise ValueError("the truth track has no position at some window time")
    lat_all = truth["lat"].to_numpy(dtype=float)
    lon_all = truth["lon"].to_numpy(dtype=float)
    ids = np.asarray(beacons.beacon_id, dtype=object)
    windows: list[Window] = []
    rows: dict[str, list[Any]] = {"time": [], "toa_s": [], "beacon_id": [], "stored": []}
    for t, k in zip(wtimes, pos, strict=True):
        wb = window_beacons(beacons, info, t)
        ranges = beacon_ranges_m(lat_all[k : k + 1], lon_all[k : k + 1], wb)
        mu = predicted_toa_s(ranges, wb, model)[0]
        pd_i = detection_prob(ranges, model)[0]
        s = len(wb.index)
        u_det = rng.random(s)
        err = model.toa_sigma_s * rng.standard_normal(s)
        u_mp = rng.random(s)
        delay = model.multipath_delay_s * rng.standard_exponential(s)
        detected = u_det < pd_i
        toa = mu + err + np.where(u_mp < model.multipath_fraction, delay, 0.0)
        n_clutter = int(rng.poisson(model.clutter_rate))
        clutter = rng.uniform(0.0, info.window_s, n_clutter)

        arr = np.concatenate([toa[detected], clutter])
        lab = np.concatenate([ids[wb.index[detected]], np.full(n_clutter, None, dtype=object)])
        arr = np.round(arr, _TOA_DECIMALS) + 0.0  # quantise; + 0.0 turns -0.0 into 0.0
        inside = (arr >= 0.0) & (arr <= info.window_s)
        arr, lab = arr[inside], lab[inside]
        order = np.argsort(arr, kind="stable")
        arr, lab = arr[order], lab[order]
        distinct = np.ones(len(arr), dtype=bool)
        distinct[1:] = arr[1:] != arr[:-1]
        arr, lab = arr[distinct], lab[distinct]
        n_stored = min(len(arr), info.max_signals)
        windows.append(Window(time=t, toa_s=arr[:n_stored].copy(), beacon_id=tuple(lab[:n_stored])))
        rows["time"].extend([t] * len(arr))
        rows["toa_s"].extend(arr.tolist())
        rows["beacon_id"].extend(lab.tolist())
        rows["stored"].extend([True] * n_stored + [False] * (len(arr) - n_stored))
    record = ArrivalRecord(info.float_id, Path(f"{info.float_id}.csv"), tuple(windows))
    arrivals = pd.DataFrame(
        {
            "time": np.array(rows["time"], dtype="datetime64[ns]"),
            "toa_s": np.array(rows["toa_s"], dtype=float),
            "beacon_id": pd.Series(rows["beacon_id"], dtype=object),
            "stored": np.array(rows["stored"], dtype=bool),
        }
    )
    return record, arrivals


def summarize(mission: SimulatedMission, true_signals_below: int = 3) -> pd.DataFrame:
    """Per float: windows, mean stored TOAs per window, clutter fraction of stored TOAs,
    and the fraction of windows storing fewer than `true_signals_below` true signals."""
    out = []
    for sf in mission.floats:
        wins = sf.record.windows
        n_stored = np.array([w.n_signals for w in wins])
        n_true = np.array([sum(lab is not None for lab in w.beacon_id) for w in wins])
        total = int(n_stored.sum())
        out.append(
            {
                "float_id": sf.info.float_id,
                "windows": len(wins),
                "mean_stored_toas": float(n_stored.mean()) if len(wins) else math.nan,
                "clutter_fraction": float(1.0 - n_true.sum() / total) if total else math.nan,
                f"frac_windows_lt{true_signals_below}_true": (
                    float(np.mean(n_true < true_signals_below)) if len(wins) else math.nan
                ),
            }
        )
    return pd.DataFrame(out)


# --------------------------------------------------------------------------------------
# Scenarios


def _day(text: str) -> np.datetime64:
    return np.datetime64(text, "D").astype("datetime64[ns]")


def _read_package_csv(name: str) -> pd.DataFrame:
    text = resources.files("rafostrack").joinpath("data", name).read_text(encoding="utf-8")
    return pd.read_csv(io.StringIO(text), dtype=str, keep_default_na=False)


def dimes_scenario(
    float_ids: tuple[str, ...] | list[str] = ("759", "767", "811"), window_open_s: float = 3600.0
) -> tuple[BeaconTable, list[FloatInfo]]:
    """The DIMES sound sources and floats (real geometry, deployment dates and clock offsets).

    Source offsets are relative to the float's window, which opens `window_open_s` after
    the day's reference time (00:00Z): offset_s = transmit_offset_s - window_open_s. The
    float ids are "float759" etc. (give "759" or "float759"); window_s = 4200,
    max_signals = 4, windows at 00:00Z.
    """
    src = _read_package_csv("dimes_sound_sources.csv")
    beacons = BeaconTable(
        beacon_id=src["source_id"].to_numpy(dtype=object),
        lat=src["lat"].astype(float).to_numpy(),
        lon=src["lon"].astype(float).to_numpy(),
        offset_s=src["transmit_offset_s"].astype(float).to_numpy() - float(window_open_s),
        drift_s_per_day=src["drift_s_per_day"].astype(float).to_numpy(),
        start=np.array([_day(d) for d in src["deployed"]], dtype="datetime64[ns]"),
        end=np.full(len(src), NaT),
    )
    table = _read_package_csv("dimes_floats.csv").set_index("float")
    floats = []
    for fid in float_ids:
        key = str(fid).removeprefix("float")
        if key not in table.index:
            raise ValueError(f"unknown DIMES float {fid!r}; known: {', '.join(table.index)}")
        row = table.loc[key]
        floats.append(
            FloatInfo(
                float_id=f"float{key}",
                launch_time=_day(row["launch_date"]),
                launch_lat=float(row["launch_lat"]),
                launch_lon=float(row["launch_lon"]),
                end_time=_day(row["recovery_date"]),
                end_lat=float(row["recovery_lat"]),
                end_lon=float(row["recovery_lon"]),
                clock_offset_start_s=float(row["clock_offset_launch_s"]),
                clock_offset_end_s=float(row["clock_offset_recovery_s"]),
                window_s=4200.0,
                max_signals=4,
            )
        )
    return beacons, floats


def synthetic_scenario(
    n_beacons: int = 8,
    days: int = 60,
    rng: np.random.Generator | int | None = None,
    *,
    n_floats: int = 1,
) -> tuple[BeaconTable, list[FloatInfo]]:
    """A small array for tests and benchmarks (deterministic: `rng=None` means seed 0).

    Beacons on a ring of radius 600 km (the array ~1200 km across) around (-58, -90), with
    a random rotation, always active, no drift, transmission offsets spread evenly over
    0..1500 s in a random order. Floats launch within ~50 km of the centre on 2010-01-01
    00:00Z, with an end fix 200-400 km away after `days` days and clock offsets within
    +-2 s; window_s = 4200, max_signals = 4.
    """
    if n_beacons < 1 or n_floats < 1 or days < 1:
        raise ValueError("n_beacons, n_floats and days must be >= 1")
    gen = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(0 if rng is None else rng)
    lat0, lon0, radius_km = -58.0, -90.0, 600.0
    angle = gen.uniform(0, 2 * np.pi) + 2 * np.pi * np.arange(n_beacons) / n_beacons
    blat, blon = displace(np.full(n_beacons, lat0), np.full(n_beacons, lon0), *_polar(radius_km, angle))
    offsets = np.linspace(0.0, 1500.0, n_beacons)[gen.permutation(n_beacons)]
    beacons = BeaconTable(
        beacon_id=np.array([f"B{i + 1}" for i in range(n_beacons)], dtype=object),
        lat=np.round(blat, 4),
        lon=np.round(blon, 4),
        offset_s=np.round(offsets, 2),
        drift_s_per_day=np.zeros(n_beacons),
        start=np.full(n_beacons, NaT),
        end=np.full(n_beacons, NaT),
    )
    launch = _day("2010-01-01")
    floats = []
    for j in range(n_floats):
        la, lo = displace(lat0, lon0, *_polar(gen.uniform(0, 50), gen.uniform(0, 2 * np.pi)))
        ea, eo = displace(la, lo, *_polar(gen.uniform(200, 400), gen.uniform(0, 2 * np.pi)))
        c0, c1 = gen.uniform(-2, 2, 2)
        floats.append(
            FloatInfo(
                float_id=f"sim{j + 1}",
                launch_time=launch,
                launch_lat=round(float(la), 4),
                launch_lon=round(float(lo), 4),
                end_time=launch + ONE_DAY * days,
                end_lat=round(float(ea), 4),
                end_lon=round(float(eo), 4),
                clock_offset_start_s=round(float(c0), 2),
                clock_offset_end_s=round(float(c1), 2),
                window_s=4200.0,
                max_signals=4,
            )
        )
    return beacons, floats


def _polar(r_km: Any, angle: Any) -> tuple[NDArray, NDArray]:
    """East/north components of a displacement of `r_km` at `angle` (radians from east)."""
    return np.asarray(r_km * np.cos(angle)), np.asarray(r_km * np.sin(angle))


# --------------------------------------------------------------------------------------
# Writing a mission directory


def _iso(t: np.datetime64) -> str:
    """ISO-8601 UTC with a Z; '' for NaT; seconds unless the time has a fraction."""
    t = np.datetime64(t, "ns")
    if np.isnat(t):
        return ""
    whole = t.astype("int64") % 1_000_000_000 == 0
    return np.datetime_as_string(t, unit="s" if whole else "ns") + "Z"


def _num(x: float) -> str:
    """Shortest text that reads back to the same float ('300', '-58.149'); '' for NaN."""
    x = float(x)
    if math.isnan(x):
        return ""
    return str(int(x)) if x.is_integer() and abs(x) < 1e15 else repr(x)


def _csv(header: list[str], rows: list[list[str]]) -> str:
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(header)
    writer.writerows(rows)
    return buf.getvalue()


def _check_id(kind: str, name: str) -> None:
    if not name or name != name.strip() or any(c in name for c in ',"\n\r/\\'):
        raise ValueError(f'{kind} {name!r} cannot be written (empty, padded, or contains , " / \\ or newline)')


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int | np.integer):
        return str(int(v))
    if isinstance(v, float | np.floating):
        return repr(float(v))
    if isinstance(v, str):
        return json.dumps(v)
    raise ValueError(f"cannot write {v!r} to TOML")


def mission_config_text(mission: SimulatedMission, config_overrides: dict | None = None) -> str:
    """`rafostrack.toml`: the simulation's [model] table, then any further sections/keys.

    Overrides are validated like any config layer; a [model] key among them replaces the
    simulated value (deliberate model mismatch).
    """
    sections: dict[str, dict[str, Any]] = {"model": asdict(mission.model)}
    for name, values in (config_overrides or {}).items():
        if not isinstance(values, dict):
            raise ValueError(f"config_overrides[{name!r}] must be a dict of keys")
        sections.setdefault(name, {}).update(values)
    lines = [
        "# Written by rafostrack.simulate.write_mission. [model] holds the measurement model",
        "# the arrival times were simulated with, so that tracking uses matching settings.",
        f"# Drift: mean velocity + Ornstein-Uhlenbeck eddies (speed sd "
        f"{mission.eddy_speed_km_per_day:g} km/day, timescale {mission.eddy_timescale_days:g} days),",
        "# bridged to the end fix; true tracks are in truth/.",
    ]
    for name, values in sections.items():
        lines += ["", f"[{name}]"] + [f"{key} = {_toml_value(v)}" for key, v in values.items()]
    text = "\n".join(lines) + "\n"
    merge_layer(load_config().to_dict(), tomllib.loads(text), "rafostrack.toml (write_mission)")
    return text


def write_mission(mission: SimulatedMission, outdir: Path, config_overrides: dict | None = None) -> None:
    """Write a mission directory (every file atomically):

    beacons.csv, floats.csv, <float_id>.csv (time, toa_s, beacon_id: the true labels as
    hand labels, empty = clutter; a window that stored nothing is one row with empty
    toa_s), truth/<float_id>.csv (time, lat, lon) and rafostrack.toml ([model] as simulated,
    plus `config_overrides`, e.g. {"filter": {"particles": 2000}}).
    """
    outdir = Path(outdir)
    b = mission.beacons
    for bid in b.beacon_id:
        _check_id("beacon_id", str(bid))
    for sf in mission.floats:
        _check_id("float_id", sf.info.float_id)
    config_text = mission_config_text(mission, config_overrides)  # validate before writing

    beacon_rows = [
        [str(b.beacon_id[i]), _num(b.lat[i]), _num(b.lon[i]), _num(b.offset_s[i]), _iso(b.start[i]),
         _iso(b.end[i]), _num(b.drift_s_per_day[i])]
        for i in range(len(b))
    ]  # fmt: skip
    write_text_atomic(
        outdir / "beacons.csv",
        _csv(["beacon_id", "lat", "lon", "offset_s", "start", "end", "drift_s_per_day"], beacon_rows),
    )
    float_rows = []
    for sf in mission.floats:
        f = sf.info
        float_rows.append(
            [f.float_id, _iso(f.launch_time), _num(f.launch_lat), _num(f.launch_lon), _iso(f.end_time),
             _num(f.end_lat), _num(f.end_lon), _num(f.clock_offset_start_s), _num(f.clock_offset_end_s),
             _num(f.window_s), str(int(f.max_signals))]
        )  # fmt: skip
    float_header = [
        "float_id", "launch_time", "launch_lat", "launch_lon", "end_time", "end_lat", "end_lon",
        "clock_offset_start_s", "clock_offset_end_s", "window_s", "max_signals",
    ]  # fmt: skip
    write_text_atomic(outdir / "floats.csv", _csv(float_header, float_rows))

    for sf in mission.floats:
        rows = []
        for w in sf.record.windows:
            when = _iso(w.time)
            if w.n_signals == 0:
                rows.append([when, "", ""])
            labels = w.beacon_id if w.beacon_id is not None else (None,) * w.n_signals
            rows += [[when, f"{t:.{_TOA_DECIMALS}f}", lab or ""] for t, lab in zip(w.toa_s, labels, strict=True)]
        write_text_atomic(outdir / f"{sf.info.float_id}.csv", _csv(["time", "toa_s", "beacon_id"], rows))
        truth_rows = [
            [_iso(t), f"{la:.6f}", f"{lo:.6f}"]
            for t, la, lo in zip(
                sf.truth["time"].to_numpy(dtype="datetime64[ns]"),
                sf.truth["lat"].to_numpy(dtype=float),
                sf.truth["lon"].to_numpy(dtype=float),
                strict=True,
            )
        ]
        write_text_atomic(outdir / "truth" / f"{sf.info.float_id}.csv", _csv(["time", "lat", "lon"], truth_rows))
    write_text_atomic(outdir / "rafostrack.toml", config_text)
