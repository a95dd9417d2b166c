"""Simulate RAFOS missions (arrival files plus the true track) from the tracker's own model.

Generative model, per float (all randomness from one `numpy.random.Generator`, drawn in a
fixed order: floats in order; per float the drift, then the windows in time order):

Drift (the truth track): the tracker's own velocity-persistent motion model,
`rafostrack.motion.IntegratedOU` (velocity v = vbar + u, u an Ornstein-Uhlenbeck process per
axis with stationary sd `eddy_speed_km_per_day` and decorrelation time
`eddy_timescale_days`, position its exact integral), stepped exactly from the launch to
every day after it, up to the end time (plus the end time itself if the mission is not a
whole number of days), or for `days` days when the float has no end time. vbar is the
launch-to-end offset (local tangent plane at launch) over the duration (0 without an end
fix); the launch eddy velocity is drawn from its stationary law. When the float has an end
fix, a bridge then adds a constant extra mean current c, which with the same noise moves
the track by c (t - t_launch), found by fixed-point iteration (c += miss / duration) until
the track ends within 1 mm of the end fix; the last point is then set to the fix.

When `days` ends the windows before the end fix, the mission is cut there
(`end_at_last_window`): the truth at the last window becomes the end fix, so a written
mission is consistent (its end fix is where its record stops).

Windows. One per day at the launch's time of day, from the day after launch up to (not
beyond) the end time, and at most `days` of them. The float's position in a window is the
truth at the window time. In each window, for each beacon active then
(`BeaconTable.active_at`), using `model.measurement.window_beacons`, `beacon_ranges_m`,
`predicted_toa_s` and `detection_prob` (so simulator and tracker share one model,
including source drift and the float clock offset):
  * the signal is detected with probability Pd(range);
  * a detected signal arrives at mu + e, e ~ N(0, toa_sigma_s^2), plus, with probability
    `multipath_fraction`, a Gamma(shape `multipath_delay_shape`, mean `multipath_delay_s`)
    delay (`model.measurement.multipath_delays`); with probability `echo_fraction` a detected signal
    arrives a second time, after another such delay (an echo, labelled with its source);
  * clutter: N ~ Poisson(`clutter_rate`) signals, uniform on [0, window_s].
Arrival times are quantised to `TOA_RESOLUTION_S` (0.01 s, the files' resolution; signals
that then coincide are one received signal, keeping the first label in beacon-table order,
clutter last: a ~1e-5 per window event). Of the received signals inside [0, window_s] the
float stores the earliest `max_signals`; each stored TOA keeps the beacon that produced it
(None = clutter). A window with nothing stored is kept (written as one row, empty toa_s).

Random draws per float: the launch eddy velocity (2 normals), then 4 normals per drift
step; then per window, always in this order and whatever their use: uniform (detection),
normal (TOA error), uniform (multipath) and standard gamma (delay; a standard exponential
when the shape is 1), one of each per active beacon; when `echo_fraction` > 0, a uniform
(echo) and a standard gamma (its delay) per active beacon; then the clutter count and its times.

Scenarios are in `rafostrack.sim.scenarios`; `rafostrack.sim.mission_writer.write_mission`
writes a mission directory that `rafostrack track` reads, with the true labels as hand
labels and the truth beside it.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from ..config import ModelConfig
from ..domain import ArrivalRecord, BeaconTable, FloatInfo, Particles, Window
from ..model.geodesy import local_offsets_km, wrap_lon
from ..model.measurement import beacon_ranges_m, detection_prob, multipath_delays, predicted_toa_s, window_beacons
from ..motion import IntegratedOU

TOA_RESOLUTION_S = 0.01
_TOA_DECIMALS = 2
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
        if days is not None:
            info, truth = end_at_last_window(info, truth, record)
        out.append(SimulatedFloat(info, record, truth, arrivals))
    return SimulatedMission(beacons, out, model, float(eddy_speed_km_per_day), float(eddy_timescale_days))


def end_at_last_window(info: FloatInfo, truth: pd.DataFrame, record: ArrivalRecord) -> tuple[FloatInfo, pd.DataFrame]:
    """A float whose windows stop before its end fix (`days` cut the mission short) ends at
    its last window instead: the truth is cut there and becomes the end fix, and the end clock
    offset is the linear clock model's value then. Otherwise `info` and `truth` unchanged."""
    if not (info.has_end_fix and record.windows) or record.windows[-1].time >= info.end_time:
        return info, truth
    end = np.datetime64(record.windows[-1].time).astype("datetime64[ns]")
    kept = truth[truth["time"].to_numpy(dtype="datetime64[ns]") <= end].reset_index(drop=True)
    last = kept.iloc[-1]
    new = dataclasses.replace(
        info,
        end_time=end,
        end_lat=float(last["lat"]),
        end_lon=float(last["lon"]),
        clock_offset_end_s=float(info.clock_offset_s(end)),
    )
    return new, kept


def _track_times(info: FloatInfo, days: int | None) -> NDArray[np.datetime64]:
    """Launch, then every day, then the end time (or launch + `days` without an end fix)."""
    launch = np.datetime64(info.launch_time).astype("datetime64[ns]")
    if not np.isnat(info.end_time):
        end = np.datetime64(info.end_time).astype("datetime64[ns]")
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
    """The true track: the integrated Ornstein-Uhlenbeck motion model around the
    launch-to-end mean velocity, bridged to the end fix (module docstring)."""
    times = _track_times(info, days)
    dt = np.diff(times) / ONE_DAY  # days
    duration = float((times[-1] - times[0]) / ONE_DAY)
    if info.has_end_fix and duration > 0:
        east, north = local_offsets_km(info.end_lat, info.end_lon, info.launch_lat, info.launch_lon)
        vbar = np.array([float(east), float(north)]) / duration
    else:
        vbar = np.zeros(2)
    eddy0 = rng.standard_normal(2)  # the launch eddy velocity, in units of its sd
    noise = rng.standard_normal((len(dt), 4, 1))
    lat0, lon0 = info.launch_lat, float(wrap_lon(info.launch_lon))

    def integrate(current: NDArray) -> tuple[NDArray, NDArray]:
        """Positions at `times` with mean current `current` and the drawn eddies."""
        model = IntegratedOU(eddy_speed_km_per_day, eddy_timescale_days, (float(current[0]), float(current[1])))
        state = Particles(np.array([lat0]), np.array([lon0]), (current + eddy_speed_km_per_day * eddy0)[None, :])
        lat, lon = np.empty(len(times)), np.empty(len(times))
        lat[0], lon[0] = lat0, lon0
        for k, step in enumerate(dt):
            state = model.step(state, float(step), noise[k])
            lat[k + 1], lon[k + 1] = state.lat[0], state.lon[0]
        return lat, lon

    lat, lon = integrate(vbar)
    if info.has_end_fix and duration > 0:
        # Bridge: with the same noise, a mean current vbar + c moves every position by
        # c (t - t_launch) (the eddies do not depend on it); find c by fixed-point iteration.
        c = np.zeros(2)
        for _ in range(_BRIDGE_MAX_ITER):
            miss = np.array(local_offsets_km(info.end_lat, info.end_lon, lat[-1], lon[-1]), dtype=float)
            if np.hypot(*miss) < _BRIDGE_TOL_KM:
                break
            c += miss / duration
            lat, lon = integrate(vbar + c)
        else:
            raise RuntimeError(f"float {info.float_id!r}: the drift bridge did not converge")
        lat[-1], lon[-1] = info.end_lat, float(wrap_lon(info.end_lon))  # exact, not to 1e-6 km
    return pd.DataFrame({"time": times.astype("datetime64[ns]"), "lat": lat, "lon": lon})


def window_times(info: FloatInfo, days: int | None = None) -> NDArray[np.datetime64]:
    """Daily windows at the launch's time of day, from the day after launch to the end."""
    launch = np.datetime64(info.launch_time).astype("datetime64[ns]")
    n = days
    if not np.isnat(info.end_time):
        n_end = int((np.datetime64(info.end_time).astype("datetime64[ns]") - launch) // ONE_DAY)
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
    windows: list[Window] = []
    rows: dict[str, list[Any]] = {"time": [], "toa_s": [], "beacon_id": [], "stored": []}
    for t, k in zip(wtimes, pos, strict=True):
        arr, lab = _received(*_signals(beacons, info, model, t, lat_all[k : k + 1], lon_all[k : k + 1], rng), info)
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


def _signals(
    beacons: BeaconTable,
    info: FloatInfo,
    model: ModelConfig,
    t: np.datetime64,
    lat: NDArray[np.float64],
    lon: NDArray[np.float64],
    rng: np.random.Generator,
) -> tuple[NDArray[np.float64], NDArray[np.object_]]:
    """The signals received in the window at `t` from position (lat, lon) (1-element
    arrays), unsorted, with their labels: each active beacon detected with its probability,
    its TOA with Gaussian error and (by chance) a multipath delay, optional echoes, and
    Poisson clutter uniform in the window (None label)."""
    ids = np.asarray(beacons.beacon_id, dtype=object)
    wb = window_beacons(beacons, info, t)
    ranges = beacon_ranges_m(lat, lon, wb)
    mu = predicted_toa_s(ranges, wb, model)[0]
    pd_i = detection_prob(ranges, wb, model)[0]
    s = len(wb.index)
    u_det = rng.random(s)
    err = model.toa_sigma_s * rng.standard_normal(s)
    u_mp = rng.random(s)
    delay = multipath_delays(rng, model, s)
    detected = u_det < pd_i
    toa = mu + err + np.where(u_mp < model.multipath_fraction, delay, 0.0)
    echoes = np.zeros(0)
    echo_ids = np.zeros(0, dtype=object)
    if model.echo_fraction > 0:  # drawn only then: records without echoes keep their draws
        u_echo = rng.random(s)
        echo_delay = multipath_delays(rng, model, s)
        echoed = detected & (u_echo < model.echo_fraction)
        echoes, echo_ids = (toa + echo_delay)[echoed], ids[wb.index[echoed]]
    n_clutter = int(rng.poisson(model.clutter_rate))
    clutter = rng.uniform(0.0, info.window_s, n_clutter)
    arr = np.concatenate([toa[detected], echoes, clutter])
    lab = np.concatenate([ids[wb.index[detected]], echo_ids, np.full(n_clutter, None, dtype=object)])
    return arr, lab


def _received(
    arr: NDArray[np.float64], lab: NDArray[np.object_], info: FloatInfo
) -> tuple[NDArray[np.float64], NDArray[np.object_]]:
    """What the float records of a window's signals: quantised, inside [0, window_s],
    ascending, one of each distinct time (the first)."""
    arr = np.round(arr, _TOA_DECIMALS) + 0.0  # quantise; + 0.0 turns -0.0 into 0.0
    inside = (arr >= 0.0) & (arr <= info.window_s)
    arr, lab = arr[inside], lab[inside]
    order = np.argsort(arr, kind="stable")
    arr, lab = arr[order], lab[order]
    distinct = np.ones(len(arr), dtype=bool)
    distinct[1:] = arr[1:] != arr[:-1]
    return arr[distinct], lab[distinct]


def summarize(mission: SimulatedMission, true_signals_below: int = 3) -> pd.DataFrame:
    """Per float: windows, mean stored TOAs per window, clutter fraction of stored TOAs,
    and the fraction of windows storing fewer than `true_signals_below` true signals."""
    out = []
    for sf in mission.floats:
        wins = sf.record.windows
        n_stored = np.array([w.n_signals for w in wins])
        n_true = np.array([sum(lab is not None for lab in w.beacon_id or ()) for w in wins])
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
