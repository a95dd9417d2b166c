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
  that the shared sound speed hinges on is left out of it (`hinging_sources`);
- `noise.fit_clutter_rate`: clutter signals per window;
- `detection.fit_detection`: each beacon's peak detection probability and half range;
- `window_check`: the listening window's length against the latest TOAs and the clutter.

The next pass tracks with these values (`Calibration.calibrated`: typed `ModelValues`
beside the user's configuration, which is never rewritten). A value the user set in a
config file or flag is kept as set, not estimated; every estimate is reported in run.json.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from ..config import Config
from ..domain import ArrivalRecord, BeaconTable, FloatInfo
from ..model import measurement as m
from ..problem import FloatProblem, ModelValues
from ..summaries.estimates import Estimate
from . import kalman
from .association import fit_association
from .detection import fit_detection, heard_nowhere
from .metadata_checks import MetadataCheck, timing_checks, z_of
from .noise import MultipathEM
from .release import Key, key_of, releasable, released_problem, used, with_supported_fixes
from .timing_problem import (
    MIN_ARRIVALS as MIN_ARRIVALS,
)
from .timing_problem import (
    corrected_beacons,
    hinging_sources,
    timing_problem,
    track_at,
    without_sources,
)
from .window_check import window_check, with_supported_window

INITIAL_CLOCK_RATE_SD_S_PER_DAY = 0.01
MAX_RELEASES = 4  # table values released at most per calibration (`_checked_fit`)
RELEASE_TRIALS = 3  # contradicted values tried per release


@dataclass(frozen=True)
class Calibration:
    """Estimated values: the model's (`ModelValues`, typed, beside the user's configuration),
    the beacon table and float with their corrections, and the position covariance the
    nuisances leave undetermined at each node time."""

    model: ModelValues
    beacons: BeaconTable
    info: FloatInfo
    report: dict[str, Any] = field(default_factory=dict)
    nuisance_time: NDArray[np.datetime64] = field(default_factory=lambda: np.zeros(0, "datetime64[ns]"))
    nuisance_cov_km2: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 2, 2)))
    hyper: kalman.Hyper | None = None  # the Kalman smoother's fitted hyperparameters
    checks: tuple[MetadataCheck, ...] = ()  # the table values against the arrivals (`metadata_checks`)

    def calibrated(self, problem: FloatProblem) -> FloatProblem:
        """`problem` as calibrated: the corrected beacon table and float, tracked with the
        estimated model values beside its (the user's) configuration."""
        return FloatProblem(self.beacons, self.info, problem.config, self.model)

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


@dataclass(frozen=True)
class _TimingFit:
    """The timing fit (`kalman.fit`) and the problem it was fitted to."""

    problem: kalman.Problem  # without the sources left out
    heard: NDArray[np.intp]  # the beacon-table rows of its sources
    fit: kalman.KalmanFit
    left_out: dict[str, int]  # source: its confident arrivals (`hinging_sources`)
    multipath_fraction: float  # the last multipath EM estimate (where the association fit starts)
    priors: kalman.KalmanPriors
    mid: NDArray[np.float64]  # the drift reference of each source (days)


@dataclass(frozen=True)
class _DetectionFit:
    """The beacon table with the fitted detection, each fit's report, the beacons heard nowhere."""

    beacons: BeaconTable
    report: dict[str, Any]
    heard_nowhere: list[str]


def calibrate(
    estimate: Estimate, record: ArrivalRecord, problem: FloatProblem, start: kalman.Hyper | None = None
) -> Calibration | None:
    """Estimate the record's nuisances from a first pass's `estimate` (module docstring);
    None when it has too few confident arrivals. Keys the user set (`problem.config.explicit`)
    keep their values. The hyperparameter search starts at `start` (a previous calibration's
    `hyper`: the optimum moves little between passes) or else at the configured values."""
    built = timing_problem(estimate, problem.beacons, problem.info, problem.config)
    if built is None:
        return None
    timing = _fit_timing(built, problem, start)
    checks: list[MetadataCheck] = []
    if problem.config.checks.enabled:
        timing, checks = _checked_fit(built, timing, problem)
    fit, explicit = timing.fit, problem.config.explicit
    timed_values = ModelValues.rounded(_timing_values(fit), explicit)
    corrected = corrected_beacons(problem.beacons, timing.heard, fit, _speeds_fitted(problem.config))
    clocked = dataclasses.replace(problem.info, clock_residual=(timing.problem.time, fit.clock_s))
    clocked = with_supported_fixes(clocked, checks)
    timed = timed_values.applied(problem.config).model
    detection = _fit_detection(estimate, record, problem, corrected, clocked, timed)
    associated, association_report = _fit_noise(record, timing, detection.beacons, clocked, timed)
    if problem.config.checks.enabled:
        window = window_check(record, problem.info, associated.clutter_rate, problem.config.checks.launch_z_score)
        clocked, clutter_rate = with_supported_window(clocked, associated.clutter_rate, window, record)
        associated = dataclasses.replace(associated, clutter_rate=clutter_rate)
        checks.append(window)
    model = timed_values.merged(ModelValues.rounded(_association_values(associated), explicit))
    report = _report(timing, model, problem, detection, association_report)
    return Calibration(
        model, detection.beacons, clocked, report, timing.problem.time, fit.nuisance_cov_km2, fit.hyper, tuple(checks)
    )


def _speeds_fitted(config: Config) -> bool:
    """Whether the sound speeds are fitted: not when the user set the sound speed."""
    return ("model", "sound_speed_m_s") not in config.explicit


def _fit_timing(
    built: tuple[kalman.Problem, NDArray[np.intp], NDArray[np.float64]],
    problem: FloatProblem,
    start: kalman.Hyper | None,
) -> _TimingFit:
    """Stage 1, timing: the batch Kalman smoother's fit (hyperparameters by marginal
    likelihood, multipath by EM), again without the sources the sound speed hinges on."""
    timing, heard, mid = built
    config = problem.config
    model, motion = config.model, config.motion
    noise = MultipathEM(model)
    if start is None:
        start = kalman.Hyper(
            motion.velocity_sd_km_per_day, motion.decorrelation_days, model.toa_sigma_s, INITIAL_CLOCK_RATE_SD_S_PER_DAY
        )
    # A sound speed the user set is held: its corrections get a prior sd of 1 mm/s.
    speeds_fitted = _speeds_fitted(config)
    priors = (
        kalman.KalmanPriors()
        if speeds_fitted
        else kalman.KalmanPriors(sound_speed_m_s=1e-3, beacon_sound_speed_m_s=1e-3)
    )
    lower = kalman.Hyper.lower_with_clock_floor(config.calibrate.min_clock_rate_sd_s_per_day)
    fit = kalman.fit(timing, start, noise.weight_of, mid, priors=priors, hyper_lower=lower)
    left_out: dict[str, int] = {}
    # A sound speed the user set does not move: no source can hinge it.
    hinging = hinging_sources(timing, fit, priors) if speeds_fitted else np.zeros(timing.n_heard, dtype=bool)
    if hinging.any():
        counts = np.bincount(timing.beacon, minlength=timing.n_heard)
        left_out = {str(problem.beacons.beacon_id[heard[h]]): int(counts[h]) for h in np.flatnonzero(hinging)}
        timing, mid = without_sources(timing, mid, hinging)
        heard = heard[~hinging]
        fit = kalman.fit(timing, fit.hyper, noise.weight_of, mid, priors=priors, hyper_lower=lower)
    return _TimingFit(timing, heard, fit, left_out, noise.model.multipath_fraction, priors, mid)


def _checked_fit(
    built: tuple[kalman.Problem, NDArray[np.intp], NDArray[np.float64]], timing: _TimingFit, problem: FloatProblem
) -> tuple[_TimingFit, list[MetadataCheck]]:
    """The table values checked against the arrivals (`metadata_checks`), and the contradicted
    ones released one at a time (`release`): of the `RELEASE_TRIALS` strongest
    contradictions not yet released, the one whose release gives the fit of highest
    evidence, until none is left (at most `MAX_RELEASES`). The fit and its checks, each with
    the value the track uses."""
    released: set[Key] = set()
    release_sources = problem.config.checks.release_sources
    for _ in range(MAX_RELEASES + 1):
        checks = timing_checks(timing.problem, timing.fit, timing.priors, timing.heard, timing.mid, problem.beacons,
                               problem.info, problem.config.checks)  # fmt: skip
        candidates = [c for c in checks if releasable(c, release_sources) and key_of(c) not in released]
        if not candidates or len(released) == MAX_RELEASES:
            break
        trials = []
        for check in sorted(candidates, key=z_of, reverse=True)[:RELEASE_TRIALS]:
            keys = released | {key_of(check)}
            trials.append(
                (_fit_timing(released_problem(built, keys, problem.beacons), problem, timing.fit.hyper), keys)
            )
        timing, released = max(trials, key=lambda trial: trial[0].fit.log_evidence)
    # A value contradicted only before a release (an echo) is not a finding.
    return timing, [used(c, release_sources) for c in checks]


def _timing_values(fit: kalman.KalmanFit) -> dict[str, float]:
    """The model values the timing fit estimates (`ModelValues` keys), at the fit's precision."""
    hyper = fit.hyper
    return {
        "sound_speed_m_s": fit.sound_speed_m_s,
        "toa_sigma_s": hyper.toa_sigma_s,
        "mean_current_east_km_per_day": float(fit.mean_current_km_per_day[0]),
        "mean_current_north_km_per_day": float(fit.mean_current_km_per_day[1]),
        "velocity_sd_km_per_day": hyper.velocity_sd_km_per_day,
        "decorrelation_days": hyper.decorrelation_days,
        # The random walk with the same long-time spread: D^2 = 2 sigma_v^2 T per axis per day.
        "diffusion_km_per_day": hyper.velocity_sd_km_per_day * float(np.sqrt(2 * hyper.decorrelation_days)),
    }


def _association_values(associated: m.ModelConfig) -> dict[str, float]:
    """The model values the association fit estimates (`ModelValues` keys), at the fit's precision."""
    return {
        "multipath_fraction": associated.multipath_fraction,
        "multipath_delay_s": associated.multipath_delay_s,
        "echo_fraction": associated.echo_fraction,
        "clutter_rate": associated.clutter_rate,
    }


def _fit_detection(
    estimate: Estimate,
    record: ArrivalRecord,
    problem: FloatProblem,
    corrected: BeaconTable,
    clocked: FloatInfo,
    timed: m.ModelConfig,
) -> _DetectionFit:
    """Stage 3, detection: each beacon's fitted detection (`_detection`) in the corrected
    table, unless the user (`[model] p_detect`, `detection_range_km`) or the beacon table sets it."""
    beacons = problem.beacons
    detection_set = problem.config.explicit & {("model", "p_detect"), ("model", "detection_range_km")}
    if beacons.p_detect is not None or beacons.detection_range_km is not None or detection_set:
        return _DetectionFit(corrected, {}, [])
    p, r50, report = _detection(estimate, record, corrected, clocked, timed)
    nowhere = [str(beacons.beacon_id[i]) for i in np.flatnonzero(np.isfinite(p)) if heard_nowhere(p[i])]
    return _DetectionFit(dataclasses.replace(corrected, p_detect=p, detection_range_km=r50), report, nowhere)


def _fit_noise(
    record: ArrivalRecord, timing: _TimingFit, beacons: BeaconTable, clocked: FloatInfo, timed: m.ModelConfig
) -> tuple[m.ModelConfig, dict[str, Any]]:
    """Stage 4, noise: multipath, echoes and clutter by the association EM over the whole
    record (`association.fit_association`), at the timing fit's track."""
    fit = timing.fit
    lat, lon = track_at(record, timing.problem.time, fit.lat, fit.lon)
    position_sd = float(np.median(np.sqrt(0.5 * np.trace(fit.position_cov_km2, axis1=1, axis2=2))))
    start_noise = dataclasses.replace(timed, multipath_fraction=max(timing.multipath_fraction, 0.02))
    return fit_association(record, lat, lon, beacons, clocked, start_noise, position_sd)


def _report(
    timing: _TimingFit,
    model: ModelValues,
    problem: FloatProblem,
    detection: _DetectionFit,
    association_report: dict[str, Any],
) -> dict[str, Any]:
    """Stage 5: run.json's `calibration`: what was used, fitted, left out and kept as configured."""
    fit, explicit = timing.fit, problem.config.explicit
    direct = fit.weight > 0.5
    return {
        "arrivals_used": len(timing.problem.toa_s),
        "sources_left_out": timing.left_out,  # source: its confident arrivals (`hinging_sources`)
        "sources_heard_nowhere": detection.heard_nowhere,  # detection fitted at p's lower bound (`heard_nowhere`)
        "windows_used": int(np.unique(timing.problem.node).size),
        "residual_rms_s": round(float(np.sqrt(np.mean(fit.toa_residual_s[direct] ** 2))), 3),
        "clock_rate_sd_s_per_day": round(fit.hyper.clock_rate_sd_s_per_day, 5),
        "association": association_report,
        "log_evidence": round(fit.log_evidence, 2),
        "values": {f"[{s}] {k}": v for (s, k), v in model.items()},
        "kept_as_configured": sorted(f"[{s}] {k}" for s, k in explicit if (s, k) in ModelValues.keys()),
        "beacons": _beacon_report(timing, problem.beacons, detection.report),
        "clock_residual_s": {"max_abs": round(float(np.abs(fit.clock_s).max()), 3), "nodes": len(fit.clock_s)},
        "nuisance_sd_km": {
            "median": round(float(np.median(np.sqrt(np.trace(fit.nuisance_cov_km2, axis1=1, axis2=2)))), 3)
        },
    }


def _beacon_report(
    timing: _TimingFit, beacons: BeaconTable, detection_report: dict[str, Any]
) -> dict[str, dict[str, float]]:
    """Timing corrections of the beacons in the timing fit; the detection of every beacon
    whose fit is used, heard or not (a source fitted as heard nowhere is one a user will
    want to see)."""
    ids = [str(b) for b in beacons.beacon_id]
    fit = timing.fit
    report: dict[str, dict[str, float]] = {
        ids[i]: {
            "offset_correction_s": round(float(fit.offset_s[h]), 3),
            "drift_correction_s_per_day": round(float(fit.drift_s_per_day[h]), 5),
            "sound_speed_m_s": round(float(fit.beacon_sound_speed_m_s[h]), 2),
        }
        for h, i in enumerate(timing.heard)
    }
    for name, detection in detection_report.items():
        report.setdefault(name, {}).update(detection)
    return report
