"""Calibration: the nuisances of real data, estimated from the record itself.

Real records do not match the configured model: the effective sound speed differs by a few
m/s (3-4 s of arrival time at 800 km), source clocks drift from their catalogue values,
the float clock wanders, each source is heard to its own range, multipath delays some
arrivals, clutter and noise levels vary, and the float's drift is the ocean's. A first
tracking pass with robust settings gives positions and labels; from its confident labels:

- `kalman.fit`: a batch Kalman smoother of the track with the float clock's residual and
  the timing parameters in the state (shared and per-source sound speed, source offset and
  drift corrections, the mean current), its hyperparameters (eddy velocity sd and time
  scale, TOA noise sd, clock wander) by maximum marginal likelihood and multipath by EM
  (`noise.fit_multipath`); it also gives the position variance those nuisances leave
  undetermined, which the tracker adds to its own. A source heard on a couple of arrivals
  that the shared sound speed hinges on is left out of it (`_hinging_sources`);
- `noise.fit_clutter_rate`: clutter signals per window;
- `detection.fit_detection`: each beacon's peak detection probability and half range.

The second pass tracks with these values (`Calibration.apply`). A value the user set in a
config file or flag is kept as set, not estimated; every estimate is reported in run.json.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Set
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from .. import model as m
from ..config import Config, with_overrides
from ..domain import ArrivalRecord, BeaconTable, FloatInfo, elapsed_days
from ..estimates import Estimate
from . import kalman
from .association import fit_association
from .detection import fit_detection, heard_nowhere
from .noise import direct_probability, fit_multipath

MIN_ARRIVALS = 60  # fewer confident arrivals than this: no calibration
# A source heard on at most this many confident arrivals is left out of the calibration
# when leaving it out moves the shared sound speed by more than the speed's posterior sd
# (`_hinging_sources`).
LOW_SUPPORT_ARRIVALS = 2
CONFIDENT_PROB = 0.9
INITIAL_CLOCK_RATE_SD_S_PER_DAY = 0.01

# The config keys calibration may set, (section, key).
CALIBRATED_KEYS = (
    ("model", "sound_speed_m_s"),
    ("model", "toa_sigma_s"),
    ("model", "multipath_fraction"),
    ("model", "multipath_delay_s"),
    ("model", "clutter_rate"),
    ("model", "echo_fraction"),
    ("motion", "mean_current_east_km_per_day"),
    ("motion", "mean_current_north_km_per_day"),
    ("motion", "velocity_sd_km_per_day"),
    ("motion", "decorrelation_days"),
    ("motion", "diffusion_km_per_day"),
)


@dataclass(frozen=True)
class Calibration:
    """Estimated values: config keys, the beacon table and float with their corrections, and
    the position covariance the nuisances leave undetermined at each node time."""

    values: dict[tuple[str, str], float]
    beacons: BeaconTable
    info: FloatInfo
    report: dict[str, Any] = field(default_factory=dict)
    nuisance_time: NDArray[np.datetime64] = field(default_factory=lambda: np.zeros(0, "datetime64[ns]"))
    nuisance_cov_km2: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 2, 2)))
    hyper: kalman.Hyper | None = None  # the Kalman smoother's fitted hyperparameters

    def apply(self, config: Config) -> Config:
        """`config` with the estimated keys set."""
        return _with_values(config, self.values, set())

    def nuisance_cov_at(self, times: NDArray[np.datetime64]) -> NDArray[np.float64]:
        """(n, 2, 2) nuisance covariance at `times`, from the nearest node."""
        if len(self.nuisance_time) == 0:
            return np.zeros((len(times), 2, 2))
        t = np.asarray(times, dtype="datetime64[ns]").astype(np.int64)
        nodes = self.nuisance_time.astype("datetime64[ns]").astype(np.int64)
        right = np.clip(np.searchsorted(nodes, t), 1, len(nodes) - 1) if len(nodes) > 1 else np.zeros(len(t), int)
        left = np.maximum(right - 1, 0)
        nearest = np.where(np.abs(nodes[left] - t) <= np.abs(nodes[right] - t), left, right)
        return self.nuisance_cov_km2[nearest]


def _problem(
    estimate: Estimate, beacons: BeaconTable, info: FloatInfo, config: Config
) -> tuple[kalman.Problem, NDArray[np.intp], NDArray[np.float64]] | None:
    """The smoother's problem from a first pass's confident labels (`CONFIDENT_PROB`, not in
    ambiguous windows): nodes at the launch, the labelled windows and the end fix, nominal
    positions from the first pass; the heard beacons' table rows and drift references."""
    labels, track = estimate.labels, estimate.track
    clear = track.loc[~track["ambiguous"], "time"]
    sure = labels[labels["beacon_id"].notna() & (labels["prob"] >= CONFIDENT_PROB) & labels["time"].isin(clear)]
    if len(sure) < MIN_ARRIVALS:
        return None
    positions = track.set_index("time")
    window_t = np.unique(sure["time"].to_numpy(dtype="datetime64[ns]"))
    launch_t = np.asarray(info.launch_time, dtype="datetime64[ns]")[()]
    times = [launch_t, *window_t[window_t > launch_t]]
    lat = [info.launch_lat, *positions.loc[times[1:], "lat"].to_numpy()]
    lon = [info.launch_lon, *positions.loc[times[1:], "lon"].to_numpy()]
    end_sd = None
    if config.fixes.use_end_fix and info.has_end_fix:
        end_t = np.asarray(info.end_time, dtype="datetime64[ns]")[()]
        if end_t <= times[-1]:  # a window at the end time: its node is the end fix's
            times, lat, lon = times[:-1], lat[:-1], lon[:-1]
        times.append(end_t)
        lat.append(info.end_lat)
        lon.append(info.end_lon)
        end_sd = config.fixes.end_sd_km
    node_time = np.array(times, dtype="datetime64[ns]")
    arr_t = sure["time"].to_numpy(dtype="datetime64[ns]")
    row_of = beacons.index_of()
    rows = np.array([row_of[b] for b in sure["beacon_id"]], dtype=np.intp)
    heard, beacon = np.unique(rows, return_inverse=True)
    epoch = np.where(np.isnat(beacons.start[rows]), info.launch_time, beacons.start[rows])
    days = elapsed_days(arr_t, epoch)
    mid = np.array([days[beacon == h].mean() for h in range(len(heard))])
    problem = kalman.Problem(
        time=node_time,
        lat=np.array(lat, dtype=float),
        lon=np.array(lon, dtype=float),
        launch_sd_km=config.fixes.launch_sd_km,
        end_sd_km=end_sd,
        node=np.searchsorted(node_time, arr_t),
        beacon=beacon,
        toa_s=sure["toa_s"].to_numpy(dtype=float),
        delay_s=beacons.offset_s[rows] + beacons.drift_s_per_day[rows] * days + info.clock_offset_s(arr_t),
        drift_days=days - mid[beacon],
        beacon_lat=beacons.lat[heard],
        beacon_lon=beacons.lon[heard],
        slowness_s_per_m=1.0 / config.model.sound_speed_m_s,
    )
    return problem, heard, mid


def _hinging_sources(problem: kalman.Problem, fit: kalman.KalmanFit, priors: kalman.KalmanPriors) -> NDArray[np.bool_]:
    """(H,) the heard sources the shared sound speed hinges on without support: at most
    `LOW_SUPPORT_ARRIVALS` confident arrivals, and leaving them out moves the fitted speed
    by more than its posterior sd. The speed is weakly identified (source offsets trade
    against it), so one arrival of a far source, heard nowhere else in the record, can move
    it by several m/s; such an arrival is most often clutter that fell near the source's
    predicted time (a source heard once is, by the record's own evidence, not heard there)."""
    shift, sd = kalman.sound_speed_influence(problem, fit, priors)
    counts = np.bincount(problem.beacon, minlength=problem.n_heard)
    return (counts <= LOW_SUPPORT_ARRIVALS) & (np.abs(shift) > sd)


def _without_sources(
    problem: kalman.Problem, mid: NDArray, drop: NDArray[np.bool_]
) -> tuple[kalman.Problem, NDArray[np.float64]]:
    """The problem without the arrivals of the heard sources in `drop`, and their drift references."""
    keep = ~drop[problem.beacon]
    index = np.cumsum(~drop) - 1
    return dataclasses.replace(
        problem,
        node=problem.node[keep],
        beacon=index[problem.beacon[keep]],
        toa_s=problem.toa_s[keep],
        delay_s=problem.delay_s[keep],
        drift_days=problem.drift_days[keep],
        beacon_lat=problem.beacon_lat[~drop],
        beacon_lon=problem.beacon_lon[~drop],
    ), mid[~drop]


def _with_values(config: Config, values: dict[tuple[str, str], float], explicit: Set[tuple[str, str]]) -> Config:
    """`config` with the estimated values that the user did not set."""
    layer: dict[str, dict[str, Any]] = {}
    for (section, key), value in values.items():
        if (section, key) not in explicit:
            layer.setdefault(section, {})[key] = value
    return with_overrides(config, **layer) if layer else config


def _track_at(
    record: ArrivalRecord, node_time: NDArray[np.datetime64], lat: NDArray, lon: NDArray
) -> tuple[NDArray, NDArray]:
    """Positions at every window of `record`, linear in time between the smoother's nodes."""
    t = np.array([w.time for w in record.windows], dtype="datetime64[ns]").astype(np.int64).astype(float)
    nodes = node_time.astype("datetime64[ns]").astype(np.int64).astype(float)
    unwrapped = np.degrees(np.unwrap(np.radians(lon)))
    return np.interp(t, nodes, lat), (np.interp(t, nodes, unwrapped) + 180.0) % 360.0 - 180.0


def _corrected_beacons(
    beacons: BeaconTable, heard: NDArray[np.intp], fit: kalman.KalmanFit, speeds_fitted: bool
) -> BeaconTable:
    """The beacon table with the fitted offset and drift corrections, and the fitted sound
    speeds when `speeds_fitted` (not when the user set the sound speed)."""
    offset, drift = beacons.offset_s.copy(), beacons.drift_s_per_day.copy()
    offset[heard] += fit.offset_s
    drift[heard] += fit.drift_s_per_day
    if not speeds_fitted:
        return dataclasses.replace(beacons, offset_s=offset, drift_s_per_day=drift)
    speeds = np.full(len(beacons), np.nan) if beacons.sound_speed_m_s is None else beacons.sound_speed_m_s.copy()
    speeds[heard] = fit.beacon_sound_speed_m_s
    return dataclasses.replace(beacons, offset_s=offset, drift_s_per_day=drift, sound_speed_m_s=speeds)


def _detection(
    estimate: Estimate, record: ArrivalRecord, beacons: BeaconTable, info: FloatInfo, model: m.ModelConfig
) -> tuple[NDArray, NDArray, dict[str, Any]]:
    """Per-beacon (p_detect, half range km) fitted where there are enough opportunities (NaN
    elsewhere), from the track's positions and its labels; the report of each fit, with its
    opportunities and the windows among them where the beacon was heard."""
    track = estimate.track
    at = pd.Index(track["time"]).get_indexer([w.time for w in record.windows])  # -1: not in the track
    track_lat, track_lon = track["lat"].to_numpy(), track["lon"].to_numpy()
    heard_by = estimate.labels[estimate.labels["prob"] >= 0.5].groupby("time")["beacon_id"].agg(set).to_dict()
    ranges: dict[int, list[float]] = {}
    heard: dict[int, list[float]] = {}
    for window, row in zip(record.windows, at, strict=True):
        if row < 0:
            continue
        wb = m.window_beacons(beacons, info, window.time)
        rng = m.beacon_ranges_m(track_lat[row : row + 1], track_lon[row : row + 1], wb)
        mu = m.predicted_toa_s(rng, wb, model)[0]
        h = m.horizon_s(window.toa_s, info.max_signals, info.window_s)
        names = heard_by.get(pd.Timestamp(window.time), set())
        for k, i in enumerate(wb.index):
            if 0 < mu[k] < h - 3 * model.toa_sigma_s:
                ranges.setdefault(int(i), []).append(float(rng[0, k]) / 1e3)
                heard.setdefault(int(i), []).append(float(beacons.beacon_id[i] in names))
    p = np.full(len(beacons), np.nan)
    r50 = np.full(len(beacons), np.nan)
    for i in ranges:
        fit = fit_detection(
            np.array(ranges[i]),
            np.array(heard[i]),
            model.detection_falloff_km,
            model.p_detect,
            model.detection_range_km,
        )
        if fit is not None:
            p[i], r50[i] = fit
    report = {
        str(beacons.beacon_id[i]): {
            "p_detect": round(float(p[i]), 3),
            "detection_range_km": round(float(r50[i]), 1),
            "detection_opportunities": len(heard[i]),
            "detection_heard": int(sum(heard[i])),
        }
        for i in range(len(beacons))
        if np.isfinite(p[i])
    }
    return p, r50, report


def calibrate(
    estimate: Estimate,
    record: ArrivalRecord,
    beacons: BeaconTable,
    info: FloatInfo,
    config: Config,
    explicit: set[tuple[str, str]] = frozenset(),  # type: ignore[assignment]
    start: kalman.Hyper | None = None,
) -> Calibration | None:
    """Estimate the record's nuisances from a first pass's `estimate` (module docstring);
    None when it has too few confident arrivals. Keys in `explicit` keep their values. The
    hyperparameter search starts at `start` (a previous calibration's `hyper`: the optimum
    moves little between passes) or else at the configured values."""
    built = _problem(estimate, beacons, info, config)
    if built is None:
        return None
    problem, heard, mid = built
    model = config.model
    noise = {"model": model}

    def weight_of(residual_s: NDArray, toa_sigma_s: float) -> NDArray:
        eps, tau = fit_multipath(residual_s, toa_sigma_s, noise["model"])
        noise["model"] = dataclasses.replace(
            noise["model"], toa_sigma_s=toa_sigma_s, multipath_fraction=eps, multipath_delay_s=tau
        )
        return direct_probability(residual_s, noise["model"])

    motion = config.motion
    if start is None:
        start = kalman.Hyper(
            motion.velocity_sd_km_per_day,
            motion.decorrelation_days,
            model.toa_sigma_s,
            INITIAL_CLOCK_RATE_SD_S_PER_DAY,
        )
    # A sound speed the user set is held: its corrections get a prior sd of 1 mm/s.
    speeds_fitted = ("model", "sound_speed_m_s") not in explicit
    priors = (
        kalman.KalmanPriors()
        if speeds_fitted
        else kalman.KalmanPriors(sound_speed_m_s=1e-3, beacon_sound_speed_m_s=1e-3)
    )
    lower = kalman.Hyper.lower_with_clock_floor(config.calibrate.min_clock_rate_sd_s_per_day)
    fit = kalman.fit(problem, start, weight_of, mid, priors=priors, hyper_lower=lower)
    left_out: dict[str, int] = {}
    # A sound speed the user set does not move: no source can hinge it.
    hinging = _hinging_sources(problem, fit, priors) if speeds_fitted else np.zeros(problem.n_heard, dtype=bool)
    if hinging.any():
        counts = np.bincount(problem.beacon, minlength=problem.n_heard)
        left_out = {str(beacons.beacon_id[heard[h]]): int(counts[h]) for h in np.flatnonzero(hinging)}
        problem, mid = _without_sources(problem, mid, hinging)
        heard = heard[~hinging]
        fit = kalman.fit(problem, fit.hyper, weight_of, mid, priors=priors, hyper_lower=lower)
    hyper = fit.hyper
    values: dict[tuple[str, str], float] = {
        ("model", "sound_speed_m_s"): round(fit.sound_speed_m_s, 2),
        ("model", "toa_sigma_s"): round(hyper.toa_sigma_s, 3),
        ("motion", "mean_current_east_km_per_day"): round(float(fit.mean_current_km_per_day[0]), 3),
        ("motion", "mean_current_north_km_per_day"): round(float(fit.mean_current_km_per_day[1]), 3),
        ("motion", "velocity_sd_km_per_day"): round(hyper.velocity_sd_km_per_day, 3),
        ("motion", "decorrelation_days"): round(hyper.decorrelation_days, 2),
        # The random walk with the same long-time spread: D^2 = 2 sigma_v^2 T per axis per day.
        ("motion", "diffusion_km_per_day"): round(
            hyper.velocity_sd_km_per_day * float(np.sqrt(2 * hyper.decorrelation_days)), 3
        ),
    }
    corrected = _corrected_beacons(beacons, heard, fit, speeds_fitted)
    clocked = dataclasses.replace(info, clock_residual=(problem.time, fit.clock_s))
    timed = _with_values(config, values, explicit).model
    # Detection per beacon is fitted unless the user or the beacon table sets it.
    detection_set = explicit & {("model", "p_detect"), ("model", "detection_range_km")}
    detection_report: dict[str, Any] = {}
    nowhere: list[str] = []
    if beacons.p_detect is None and beacons.detection_range_km is None and not detection_set:
        p, r50, detection_report = _detection(estimate, record, corrected, clocked, timed)
        corrected = dataclasses.replace(corrected, p_detect=p, detection_range_km=r50)
        nowhere = [str(beacons.beacon_id[i]) for i in np.flatnonzero(np.isfinite(p)) if heard_nowhere(p[i])]
    lat, lon = _track_at(record, problem.time, fit.lat, fit.lon)
    position_sd = float(np.median(np.sqrt(0.5 * np.trace(fit.position_cov_km2, axis1=1, axis2=2))))
    start_noise = dataclasses.replace(timed, multipath_fraction=max(noise["model"].multipath_fraction, 0.02))
    associated, association_report = fit_association(record, lat, lon, corrected, clocked, start_noise, position_sd)
    values |= {
        ("model", "multipath_fraction"): round(associated.multipath_fraction, 4),
        ("model", "multipath_delay_s"): round(associated.multipath_delay_s, 2),
        ("model", "echo_fraction"): round(associated.echo_fraction, 4),
        ("model", "clutter_rate"): round(associated.clutter_rate, 3),
    }
    values = {k: v for k, v in values.items() if k not in explicit}
    ids = [str(b) for b in beacons.beacon_id]
    direct = fit.weight > 0.5
    # Timing corrections of the beacons in the timing fit; the detection of every beacon whose
    # fit is used, heard or not (a source fitted as heard nowhere is one a user will want to see).
    beacon_report: dict[str, dict[str, float]] = {
        ids[i]: {
            "offset_correction_s": round(float(fit.offset_s[h]), 3),
            "drift_correction_s_per_day": round(float(fit.drift_s_per_day[h]), 5),
            "sound_speed_m_s": round(float(fit.beacon_sound_speed_m_s[h]), 2),
        }
        for h, i in enumerate(heard)
    }
    for name, detection in detection_report.items():
        beacon_report.setdefault(name, {}).update(detection)
    report = {
        "arrivals_used": len(problem.toa_s),
        "sources_left_out": left_out,  # source: its confident arrivals (`_hinging_sources`)
        "sources_heard_nowhere": nowhere,  # detection fitted at p's lower bound (`detection.heard_nowhere`)
        "windows_used": int(np.unique(problem.node).size),
        "residual_rms_s": round(float(np.sqrt(np.mean(fit.toa_residual_s[direct] ** 2))), 3),
        "clock_rate_sd_s_per_day": round(hyper.clock_rate_sd_s_per_day, 5),
        "association": association_report,
        "log_evidence": round(fit.log_evidence, 2),
        "values": {f"[{s}] {k}": v for (s, k), v in values.items()},
        "kept_as_configured": sorted(f"[{s}] {k}" for s, k in explicit if (s, k) in CALIBRATED_KEYS),
        "beacons": beacon_report,
        "clock_residual_s": {"max_abs": round(float(np.abs(fit.clock_s).max()), 3), "nodes": len(fit.clock_s)},
        "nuisance_sd_km": {
            "median": round(float(np.median(np.sqrt(np.trace(fit.nuisance_cov_km2, axis1=1, axis2=2)))), 3)
        },
    }
    return Calibration(values, corrected, clocked, report, problem.time, fit.nuisance_cov_km2, hyper)
