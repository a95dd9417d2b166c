"""The whole method for one float: calibrate, filter backwards, filter forwards guided, smooth.

    1. First pass: the filter alone, with the configured model, at three effective sound
       speeds around the configured one (`SOUND_SPEED_STEP_M_S` apart; a few hundred
       particles). The filter's log evidence, sum_t log p(y_t | y_1..t-1), is the record's
       marginal likelihood of the sound speed: a parabola through it gives the estimate
       (more points where the maximum is at an edge). The sound speed is what positions
       absorb most easily in a window (a scaled geometry looks like a moved float), so it
       is estimated from the whole record's likelihood, not from residuals.
    2. Calibration (`rafostrack.calibrate`) from the first pass nearest that sound speed.
    3. Backward pass from the recovery fix (`Tracker.run_backward`), with the calibrated model.
    4. Forward pass guided by it (`guide.BackwardGuide`), then smoothing (`smoother.smooth`).

Each step can be turned off in the configuration (`[calibrate] enabled`,
`[recovery] backward_pass`); values the user set explicitly are kept as set.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Set

import numpy as np

from .calibrate import calibrate
from .config import Config, with_overrides
from .domain import ArrivalRecord, BeaconTable, FloatInfo, PositionFix
from .estimates import Estimate, EstimateBuilder
from .guide import BackwardGuide
from .tracker import Tracker, TrackOutput

SOUND_SPEED_STEP_M_S = 12.0
SOUND_SPEED_RANGE_M_S = 36.0  # the estimate stays within this of the configured value
PROFILE_PARTICLES = 400


def _first_pass(config: Config, beacons: BeaconTable, info: FloatInfo, record: ArrivalRecord, sound_speed: float,
                particles: int) -> tuple[float, Estimate]:  # fmt: skip
    """Log evidence of the record and the filtered estimate, at one sound speed."""
    cfg = with_overrides(config, model={"sound_speed_m_s": sound_speed}, filter={"particles": particles})
    tracker = dataclasses.replace(Tracker.from_config(cfg, beacons, info), smooth=False)
    builder = EstimateBuilder(info.float_id, beacons.beacon_id, cfg.ambiguity, "filtered")
    evidence: list[float] = []

    def on_step(step):
        evidence.append(step.loglik)
        builder.add(step)

    tracker.run_filter(record, keep=False, on_step=on_step)
    return float(np.nansum(evidence)), builder.result()


def profile_sound_speed(
    config: Config, beacons: BeaconTable, info: FloatInfo, record: ArrivalRecord, particles: int = PROFILE_PARTICLES
) -> tuple[float, dict[float, float], Estimate]:
    """The sound speed maximising the record's log evidence (module docstring, step 1), the
    evidence at every speed tried, and the first-pass estimate at the speed nearest it."""
    c0 = config.model.sound_speed_m_s
    runs: dict[float, tuple[float, Estimate]] = {}
    speeds = [c0 - SOUND_SPEED_STEP_M_S, c0, c0 + SOUND_SPEED_STEP_M_S]
    while True:
        for c in speeds:
            if c not in runs:
                runs[c] = _first_pass(config, beacons, info, record, c, particles)
        tried = sorted(runs)
        best = max(tried, key=lambda c: runs[c][0])
        lo, hi = c0 - SOUND_SPEED_RANGE_M_S, c0 + SOUND_SPEED_RANGE_M_S
        if best == tried[0] and best - SOUND_SPEED_STEP_M_S >= lo:
            speeds = [best - SOUND_SPEED_STEP_M_S]
        elif best == tried[-1] and best + SOUND_SPEED_STEP_M_S <= hi:
            speeds = [best + SOUND_SPEED_STEP_M_S]
        else:
            break
    k = tried.index(best)
    estimate = best
    if 0 < k < len(tried) - 1:  # the parabola through the best point and its neighbours
        x = np.array(tried[k - 1 : k + 2])
        y = np.array([runs[c][0] for c in x])
        a, b, _ = np.polyfit(x - best, y, 2)
        if a < 0:
            estimate = float(np.clip(best - b / (2 * a), x[0], x[-1]))
    return round(estimate, 2), {c: round(runs[c][0], 2) for c in tried}, runs[best][1]


def track_record(
    beacons: BeaconTable,
    info: FloatInfo,
    config: Config,
    record: ArrivalRecord,
    *,
    also_filtered: bool = False,
    explicit: Set[tuple[str, str]] = frozenset(),
) -> TrackOutput:
    """Track one float's record with the configured method (module docstring); keys in
    `explicit`, set by the user, are not estimated."""
    first = Tracker.from_config(config, beacons, info)
    if not config.calibrate.enabled:
        guide = _backward_guide(first, record, config, None)
        return first.track(record, also_filtered=also_filtered, guide=guide)
    started = time.perf_counter()
    profile: dict[str, object] = {}
    if ("model", "sound_speed_m_s") in explicit:
        _, pass1 = _first_pass(config, beacons, info, record, config.model.sound_speed_m_s, PROFILE_PARTICLES)
        calibrated_config = config
    else:
        speed, evidence, pass1 = profile_sound_speed(config, beacons, info, record)
        calibrated_config = with_overrides(config, model={"sound_speed_m_s": speed})
        profile = {"sound_speed_m_s": speed, "log_evidence_by_sound_speed": {str(c): v for c, v in evidence.items()}}
    keep = set(explicit) | {("model", "sound_speed_m_s")}
    calibration = calibrate(pass1, record, beacons, info, calibrated_config, keep)
    if calibration is None:
        out = first.track(record, also_filtered=also_filtered)
        note = f"{info.float_id}: too few confident arrivals to calibrate; tracked with the configured values"
        return dataclasses.replace(out, warnings=[*out.warnings, note])
    report = {**calibration.report, **profile}
    calibrate_s = time.perf_counter() - started
    second = Tracker.from_config(calibration.apply(calibrated_config), calibration.beacons, calibration.info)
    guide = _backward_guide(second, record, config, pass1)
    out = second.track(record, also_filtered=also_filtered, guide=guide)
    return dataclasses.replace(out, calibration=report, calibrate_s=calibrate_s)


def _backward_guide(
    tracker: Tracker, record: ArrivalRecord, config: Config, first: Estimate | None
) -> BackwardGuide | None:
    """The backward pass, from the end fix (or, without one, from the first pass's last
    position, widened), as a guide for the forward pass; None when off or not smoothing."""
    rec = config.recovery
    if not (rec.enabled and rec.backward_pass and tracker.smooth and record.windows):
        return None
    if tracker.end_fix is not None:
        start = tracker.end_fix
    elif first is None:
        return None
    else:
        last = first.track.iloc[-1]
        sd = max(float(last["sd_km"]), 20.0)
        start = PositionFix(record.windows[-1].time, float(last["lat"]), float(last["lon"]), sd)
    return BackwardGuide(tracker.run_backward(record, start).steps, rec.guide_fraction)
