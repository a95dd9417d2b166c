"""Calibration: the nuisances of real data, estimated from the record itself.

Real records do not match the configured model: the effective sound speed differs by a few
m/s (3-4 s of arrival time at 800 km), source and float clocks wander, each source is heard
to its own range, multipath delays some arrivals, clutter and noise levels vary. A first
tracking pass with robust defaults gives positions and labels; from its confident part
(labels of probability >= 0.9, in windows whose posterior sd is small and single-moded):

- `timing.fit_timing`: the shared effective sound speed, each beacon's own sound speed,
  offset and drift corrections, and a smooth float-clock residual, jointly with small
  position changes (a robust, regularised bundle adjustment);
- `noise.fit_toa_noise`: TOA noise sd, multipath fraction and delay (maximum likelihood);
- `noise.fit_clutter_rate`: clutter signals per window;
- `detection.fit_detection`: each beacon's peak detection probability and half range;
- `drift.fit_drift`: mean current, eddy velocity sd and decorrelation time of the drift.

The second pass tracks with these values (`Calibration.apply`). A value the user set in a
config file or flag is kept as set, not estimated; every estimate is reported in run.json.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .. import model as m
from ..config import Config, with_overrides
from ..domain import ArrivalRecord, BeaconTable, FloatInfo
from ..estimates import Estimate
from .detection import fit_detection
from .drift import fit_drift
from .noise import fit_clutter_rate
from .timing import Arrivals, TimingFit, fit_timing

MIN_ARRIVALS = 60  # fewer confident arrivals than this: no calibration
CONFIDENT_PROB = 0.9
MAX_SD_KM = 8.0

# The config keys calibration may set, (section, key).
CALIBRATED_KEYS = (
    ("model", "sound_speed_m_s"),
    ("model", "toa_sigma_s"),
    ("model", "multipath_fraction"),
    ("model", "multipath_delay_s"),
    ("model", "clutter_rate"),
    ("motion", "mean_current_east_km_per_day"),
    ("motion", "mean_current_north_km_per_day"),
    ("motion", "velocity_sd_km_per_day"),
    ("motion", "decorrelation_days"),
)


@dataclass(frozen=True)
class Calibration:
    """Estimated values: config keys, the beacon table and float with their corrections."""

    values: dict[tuple[str, str], float]
    beacons: BeaconTable
    info: FloatInfo
    report: dict[str, Any] = field(default_factory=dict)

    def apply(self, config: Config) -> Config:
        """`config` with the estimated keys set."""
        layer: dict[str, dict[str, Any]] = {}
        for (section, key), value in self.values.items():
            layer.setdefault(section, {})[key] = value
        return with_overrides(config, **layer) if layer else config


def _confident_arrivals(estimate: Estimate, beacons: BeaconTable, info: FloatInfo, config: Config) -> Arrivals | None:
    """Arrivals labelled with probability >= CONFIDENT_PROB in windows with a small,
    single-moded posterior, and the GPS fixes (launch, and end if used) as windows without
    arrivals: they anchor the track, and with it the scale of the ranges (sound speed)."""
    labels, track = estimate.labels, estimate.track
    good = track[(track["sd_km"] <= MAX_SD_KM) & ~track["ambiguous"]]
    sure = labels[labels["beacon_id"].notna() & (labels["prob"] >= CONFIDENT_PROB)]
    sure = sure[sure["time"].isin(good["time"])]
    if len(sure) < MIN_ARRIVALS:
        return None
    windows = good.set_index("time").loc[sorted(sure["time"].unique())]
    times = windows.index.to_numpy(dtype="datetime64[ns]")
    lat, lon, sd = (windows[c].to_numpy(dtype=float) for c in ("lat", "lon", "sd_km"))
    fixes = [(info.launch_time, info.launch_lat, info.launch_lon, config.fixes.launch_sd_km)]
    if config.fixes.use_end_fix and info.has_end_fix:
        fixes.append((info.end_time, info.end_lat, info.end_lon, config.fixes.end_sd_km))
    fix_t = np.array([f[0] for f in fixes], dtype="datetime64[ns]")
    keep = ~np.isin(times, fix_t)
    times = np.concatenate([times[keep], fix_t])
    order = np.argsort(times, kind="stable")
    lat = np.concatenate([lat[keep], [f[1] for f in fixes]])[order]
    lon = np.concatenate([lon[keep], [f[2] for f in fixes]])[order]
    sd = np.concatenate([sd[keep], [f[3] for f in fixes]])[order]
    anchored = np.concatenate([np.zeros(keep.sum(), bool), np.ones(len(fixes), bool)])[order]
    times = times[order]
    row_of = beacons.index_of()
    return Arrivals(
        window=np.searchsorted(times, sure["time"].to_numpy(dtype="datetime64[ns]")),
        beacon=np.array([row_of[b] for b in sure["beacon_id"]], dtype=np.intp),
        toa_s=sure["toa_s"].to_numpy(dtype=float),
        time=times,
        lat=lat,
        lon=lon,
        sd_km=sd,
        anchored=anchored,
    )


def _corrected_beacons(beacons: BeaconTable, fit: TimingFit, keep_speeds: bool) -> BeaconTable:
    speeds = beacons.sound_speed_m_s if keep_speeds else np.where(fit.heard, fit.beacon_sound_speed_m_s, np.nan)
    return dataclasses.replace(
        beacons,
        offset_s=beacons.offset_s + fit.offset_s,
        drift_s_per_day=beacons.drift_s_per_day + fit.drift_s_per_day,
        sound_speed_m_s=speeds,
    )


def _detection(
    estimate: Estimate, record: ArrivalRecord, beacons: BeaconTable, info: FloatInfo, model: m.ModelConfig
) -> tuple[NDArray, NDArray, dict[str, Any]]:
    """Per-beacon (p_detect, half range km) fitted where there are enough opportunities (NaN
    elsewhere), from the track's positions and its labels."""
    track = estimate.track.set_index("time")
    heard_by = estimate.labels[estimate.labels["prob"] >= 0.5].groupby("time")["beacon_id"].agg(set)
    ranges: dict[int, list[float]] = {}
    heard: dict[int, list[float]] = {}
    for window in record.windows:
        if window.time not in track.index:
            continue
        row = track.loc[window.time]
        wb = m.window_beacons(beacons, info, window.time)
        rng = m.beacon_ranges_m(np.array([row["lat"]]), np.array([row["lon"]]), wb)
        mu = m.predicted_toa_s(rng, wb, model)[0]
        h = m.horizon_s(window.toa_s, info.max_signals, info.window_s)
        names = heard_by.get(window.time, set())
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
        str(beacons.beacon_id[i]): {"p_detect": round(float(p[i]), 3), "detection_range_km": round(float(r50[i]), 1)}
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
) -> Calibration | None:
    """Estimate the record's nuisances from a first pass's `estimate` (module docstring);
    None when it has too few confident arrivals. Keys in `explicit` keep their values."""
    model = config.model
    arrivals = _confident_arrivals(estimate, beacons, info, config)
    if arrivals is None:
        return None
    fit, noise = fit_timing(arrivals, beacons, info, model, fix_sound_speed=("model", "sound_speed_m_s") in explicit)
    sigma, eps, tau = noise.toa_sigma_s, noise.multipath_fraction, noise.multipath_delay_s
    clutter = fit_clutter_rate(estimate.labels["p_clutter"].to_numpy(dtype=float), record, info)
    values: dict[tuple[str, str], float] = {
        ("model", "sound_speed_m_s"): round(fit.sound_speed_m_s, 2),
        ("model", "toa_sigma_s"): round(sigma, 3),
        ("model", "multipath_fraction"): round(eps, 4),
        ("model", "multipath_delay_s"): round(tau, 2),
        ("model", "clutter_rate"): round(max(clutter, 0.05), 3),
    }
    drift = fit_drift(fit.track)  # the fitted track: smooth, and corrected for the timing errors
    if drift is not None:
        mean, sd, timescale = drift
        values |= {
            ("motion", "mean_current_east_km_per_day"): round(float(mean[0]), 3),
            ("motion", "mean_current_north_km_per_day"): round(float(mean[1]), 3),
            ("motion", "velocity_sd_km_per_day"): round(sd, 3),
            ("motion", "decorrelation_days"): round(timescale, 2),
        }
    values = {k: v for k, v in values.items() if k not in explicit}
    keep_speeds = ("model", "sound_speed_m_s") in explicit or beacons.sound_speed_m_s is not None
    corrected = _corrected_beacons(beacons, fit, keep_speeds)
    fitted_model = with_overrides(config, model={k: v for (s, k), v in values.items() if s == "model"}).model
    p, r50, detection_report = _detection(estimate, record, corrected, info, fitted_model)
    if beacons.p_detect is None and beacons.detection_range_km is None:
        corrected = dataclasses.replace(corrected, p_detect=p, detection_range_km=r50)
    clocked = dataclasses.replace(info, clock_residual=(fit.clock_knots, fit.clock_s))
    ids = [str(b) for b in beacons.beacon_id]
    report = {
        "arrivals_used": len(arrivals.toa_s),
        "windows_used": len(arrivals.time),
        "residual_rms_s": round(float(np.sqrt(np.mean(np.clip(fit.residual_s, -30, 30) ** 2))), 3),
        "values": {f"[{s}] {k}": v for (s, k), v in values.items()},
        "kept_as_configured": sorted(f"[{s}] {k}" for s, k in explicit if (s, k) in CALIBRATED_KEYS),
        "beacons": {
            ids[i]: {
                "offset_correction_s": round(float(fit.offset_s[i]), 3),
                "drift_correction_s_per_day": round(float(fit.drift_s_per_day[i]), 5),
                "sound_speed_m_s": round(float(fit.beacon_sound_speed_m_s[i]), 2),
                **detection_report.get(ids[i], {}),
            }
            for i in range(len(ids))
            if fit.heard[i]
        },
        "clock_residual_s": {
            "max_abs": round(float(np.abs(fit.clock_s).max()), 3),
            "knots": len(fit.clock_s),
        },
    }
    return Calibration(values, corrected, clocked, report)
