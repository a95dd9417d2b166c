"""One stress float (`rafostrack.sim.stress`): its draws (launch and drift, detection, sound
speeds, clocks, outages), then its windows in time order, and what happened to it.

Every draw comes from the mission's Generator in a fixed order; the end clocks and the
surfacing from their own (`substream`), so that turning those knobs on leaves every other
draw as it was.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from ..domain import ArrivalRecord, BeaconTable, FloatInfo, NaT, Window
from ..model.geodesy import range_m
from .stress_config import StressConfig
from .stress_world import DAY_NS, Eddy, Geometry, launch_position, simulate_track

TOA_DECIMALS = 2
DEFAULT_SOUND_SPEED_M_S = 1480.0  # the tracker's default: the truth differs from it
MAX_DRAWS = 200
CLOCK_STREAM = 32  # `substream` key of the end clocks and surfacing (`stress.FAULT_STREAM`: the faults)


@dataclass(frozen=True)
class StressFloat:
    """A simulated float: floats.csv's row, its arrival record, its true track and its events."""

    info: FloatInfo
    record: ArrivalRecord
    truth: pd.DataFrame  # time, lat, lon (daily at the window times, plus launch and end)
    events: dict[str, Any] = field(default_factory=dict)


def substream(rng: np.random.Generator, key: int) -> np.random.Generator:
    """A generator of its own for the seed `rng` was made from: the child `key` of its seed
    sequence, whatever `rng` has drawn (and drawing nothing from it)."""
    seq = rng.bit_generator.seed_seq
    if not isinstance(seq, np.random.SeedSequence):
        raise ValueError("the stress generator needs a Generator made from a seed (np.random.default_rng(seed))")
    return np.random.default_rng(np.random.SeedSequence(seq.entropy, spawn_key=(*seq.spawn_key, key)))


# --------------------------------------------------------------------------------------
# Arrivals


def covered_fraction(truth: pd.DataFrame, beacons: BeaconTable, range_km: NDArray[np.float64]) -> float:
    """Fraction of the truth's days with at least 3 sources within `range_km` (per beacon)."""
    r = range_m(truth["lat"].to_numpy()[:, None], truth["lon"].to_numpy()[:, None], beacons.lat, beacons.lon)
    return float(np.mean((r / 1e3 < range_km[None, :]).sum(axis=1) >= 3))


def _window_days(cfg: StressConfig, rng: np.random.Generator) -> tuple[NDArray[np.int64], list[list[int]]]:
    """Days (1..days) with a window, after gaps and missing days; and the gaps as day lists."""
    days = np.arange(1, cfg.days + 1)
    keep = np.ones(len(days), dtype=bool)
    gaps = []
    if cfg.gaps:
        for _ in range(rng.integers(cfg.gap_count[0], cfg.gap_count[1] + 1)):
            length = int(rng.integers(cfg.gap_days[0], cfg.gap_days[1] + 1))
            first = int(rng.integers(10, cfg.days - length - 10))
            keep[first : first + length] = False
            gaps.append([first + 1, first + length])
        keep &= rng.random(len(days)) >= cfg.missing_day_prob
    return days[keep], gaps


@dataclass(frozen=True)
class _FloatDraws:
    """A float's draws before its windows (`_draw_float`): drift, per-float and per-beacon
    properties, clock wander and source outages (beacon, first day, day after the last)."""

    launch: tuple[float, float]
    truth: pd.DataFrame
    eddies: list[Eddy]
    covered: float
    toa_sd: float
    mp_frac: float
    p_max: NDArray[np.float64]
    r50: NDArray[np.float64]
    width: NDArray[np.float64]
    c_beacon: NDArray[np.float64]
    drift_error: NDArray[np.float64]
    wander_amp: float
    wander_period: float
    wander_phase: float
    outages: list[tuple[int, int, int]]


def _draw_drift(
    float_id: str,
    beacons: BeaconTable,
    geometry: Geometry,
    cfg: StressConfig,
    all_times: NDArray,
    rng: np.random.Generator,
) -> dict[str, Any]:
    """Launch, drift and the detection properties, drawn again until the drift stays inside
    the array (`StressConfig.min_covered_fraction`)."""
    n_b = len(beacons)
    for _ in range(MAX_DRAWS):
        launch = launch_position(beacons, rng)
        truth, eddies = simulate_track(launch, all_times, geometry, cfg, rng)
        # Per-float and per-beacon properties, drawn in this order.
        toa_sd = rng.uniform(*cfg.toa_sd_s)
        mp_frac = rng.uniform(*cfg.multipath_fraction) if cfg.multipath else 0.0
        p_max = rng.uniform(*cfg.p_detect, n_b) if cfg.fading else np.full(n_b, 0.9)
        r50 = rng.uniform(*cfg.range_km, n_b) if cfg.fading else np.full(n_b, 1e5)
        width = rng.uniform(*cfg.falloff_km, n_b)
        covered = covered_fraction(truth, beacons, np.minimum(r50, cfg.range_km[1]))
        if covered >= cfg.min_covered_fraction:
            return dict(launch=launch, truth=truth, eddies=eddies, covered=covered, toa_sd=toa_sd, mp_frac=mp_frac,
                        p_max=p_max, r50=r50, width=width)  # fmt: skip
    raise RuntimeError(f"{float_id}: no drift inside the array after {MAX_DRAWS} draws")


def _draw_float(
    float_id: str,
    beacons: BeaconTable,
    geometry: Geometry,
    cfg: StressConfig,
    all_times: NDArray,
    rng: np.random.Generator,
) -> _FloatDraws:
    """The drift (`_draw_drift`), then the sound speeds, source clock errors, the float
    clock's wander and the outages, in this order."""
    drift = _draw_drift(float_id, beacons, geometry, cfg, all_times, rng)
    n_b = len(beacons)
    spread = rng.normal(0.0, cfg.beacon_sound_speed_sd_m_s, n_b)
    if cfg.sound_speed_mismatch:
        c_beacon = geometry.sound_speed_m_s + spread
    else:
        c_beacon = np.full(n_b, DEFAULT_SOUND_SPEED_M_S)
    drift_error = rng.uniform(-1, 1, n_b) * cfg.source_drift_s_per_day
    wander_amp = rng.uniform(*cfg.clock_wander_s) if cfg.clock_wander else 0.0
    wander_period, wander_phase = rng.uniform(60.0, 200.0), rng.uniform(0, 2 * np.pi)
    outages = []
    if cfg.outage:
        for i in rng.choice(n_b, size=int(rng.integers(1, 3)), replace=False):
            length = int(rng.integers(cfg.outage_days[0], cfg.outage_days[1] + 1))
            first = int(rng.integers(20, max(21, cfg.days - length - 20)))
            outages.append((int(i), first, first + length))
    return _FloatDraws(**drift, c_beacon=c_beacon, drift_error=drift_error, wander_amp=wander_amp,
                       wander_period=wander_period, wander_phase=wander_phase, outages=outages)  # fmt: skip


def _end_clock(
    clock: tuple[float, float], cfg: StressConfig, side: np.random.Generator
) -> tuple[tuple[float, float], bool]:
    """The true clock offsets (launch, end), the end's drawn in `clock_end_offset_s` when
    set, and whether the float surfaced; both drawn from `side` whatever the knobs."""
    u, surfaced = side.random(), bool(side.random() >= cfg.never_surfaced_share)
    if cfg.clock_end_offset_s is not None:
        low, high = cfg.clock_end_offset_s
        clock = (clock[0], low + u * (high - low))
    return clock, surfaced


def _float_info(
    float_id: str, draws: _FloatDraws, clock: tuple[float, float], surfaced: bool, geometry: Geometry,
    cfg: StressConfig,
) -> FloatInfo:  # fmt: skip
    """floats.csv's row: launch and end fixes, the clock offsets to 0.01 s (no end fix and
    no end clock for a float that never surfaced)."""
    start = np.datetime64(geometry.start, "D").astype("datetime64[ns]")
    end_time, end_lat, end_lon, end_clock_s = NaT, math.nan, math.nan, math.nan
    if surfaced:
        end_time, end_clock_s = start + cfg.days * DAY_NS, round(float(clock[1]), 2)
        end_lat, end_lon = float(draws.truth["lat"].iloc[-1]), float(draws.truth["lon"].iloc[-1])
    return FloatInfo(
        float_id, start, draws.launch[0], draws.launch[1], end_time, end_lat, end_lon, round(float(clock[0]), 2),
        end_clock_s, geometry.window_s, cfg.max_signals,
    )  # fmt: skip


def simulate_float(
    float_id: str,
    beacons: BeaconTable,
    geometry: Geometry,
    cfg: StressConfig,
    rng: np.random.Generator,
    side: np.random.Generator | None = None,
) -> StressFloat:
    """One float: launch, drift, events, then its windows in time order; its end clock and
    surfacing from `side` (default: `substream(rng, CLOCK_STREAM)`)."""
    start = np.datetime64(geometry.start, "D").astype("datetime64[ns]")
    draws = _draw_float(float_id, beacons, geometry, cfg, start + DAY_NS * np.arange(cfg.days + 1), rng)
    days, gaps = _window_days(cfg, rng)
    launch_clock, end_clock = rng.uniform(-2.0, 2.0, 2)
    clock, surfaced = _end_clock((float(launch_clock), float(end_clock)), cfg, side or substream(rng, CLOCK_STREAM))
    truth = draws.truth
    info = _float_info(float_id, draws, clock, surfaced, geometry, cfg)
    bad = np.zeros(len(beacons), dtype=bool)
    windows = []
    for d in days:
        if cfg.bad_propagation:  # two-state Markov regime per beacon: 10% bad on average
            flip = rng.random(len(beacons))
            bad = np.where(bad, flip > 0.25, flip < 0.028)
        windows.append(_window(int(d), start, draws, clock, bad, beacons, geometry, cfg, rng))
    record = ArrivalRecord(float_id, Path(f"{float_id}.csv"), tuple(windows))
    kept = np.concatenate([[0], days, [cfg.days]]) if days[-1] != cfg.days else np.concatenate([[0], days])
    events = {**_events(draws, beacons, geometry, cfg, gaps), **_clock_events(clock, surfaced, cfg)}
    return StressFloat(info, record, truth.iloc[np.unique(kept)].reset_index(drop=True), events)


def _window(
    d: int,
    start: np.datetime64,
    draws: _FloatDraws,
    clock: tuple[float, float],
    bad: NDArray[np.bool_],
    beacons: BeaconTable,
    geometry: Geometry,
    cfg: StressConfig,
    rng: np.random.Generator,
) -> Window:
    """Day `d`'s window: the sources' arrival times (catalogue delay + source clock error +
    float clock (linear + wander) + range / sound speed), detection, noise, multipath,
    clutter; the earliest `max_signals` inside the window are stored."""
    n_b = len(beacons)
    t = start + d * DAY_NS
    lat, lon = float(draws.truth["lat"].iloc[d]), float(draws.truth["lon"].iloc[d])
    frac = d / cfg.days
    wander = (draws.wander_amp * math.sin(2 * math.pi * d / draws.wander_period + draws.wander_phase)
              * 4 * frac * (1 - frac))  # fmt: skip
    rng_m = range_m(lat, lon, beacons.lat, beacons.lon)
    epoch_days = (t - beacons.start) / DAY_NS
    arrival = (beacons.offset_s + (beacons.drift_s_per_day + draws.drift_error) * epoch_days
               + clock[0] + frac * (clock[1] - clock[0]) + wander + rng_m / draws.c_beacon)  # fmt: skip
    pd_i = draws.p_max / (1.0 + np.exp((rng_m / 1e3 - draws.r50) / draws.width)) * np.where(bad, 0.3, 1.0)
    silent = np.array([any(i == j and a <= d < b for j, a, b in draws.outages) for i in range(n_b)])
    detected = (rng.random(n_b) < pd_i) & ~silent
    noise = (
        rng.standard_t(5, n_b) * draws.toa_sd / math.sqrt(5.0 / 3.0)
        if cfg.heavy_tails
        else rng.normal(0, draws.toa_sd, n_b)
    )
    delayed = rng.random(n_b) < draws.mp_frac
    delay = np.clip(np.exp(rng.normal(math.log(20.0), 0.6, n_b)), 5.0, 60.0)
    echo = rng.random(n_b) < 0.5
    toa = arrival + noise
    ids = np.asarray(beacons.beacon_id, dtype=object)
    times_, labels = [], []
    for i in np.flatnonzero(detected):
        if not delayed[i] or echo[i]:  # the direct arrival
            times_.append(toa[i])
            labels.append(ids[i])
        if delayed[i]:  # the delayed one, replacing it or as an echo after it
            times_.append(toa[i] + delay[i])
            labels.append(ids[i])
    n_clutter = rng.poisson(cfg.clutter_rate) + (int(rng.integers(3, 7)) if rng.random() < cfg.burst_prob else 0)
    times_ += list(_clutter_toas(n_clutter, geometry.window_s, cfg.clutter_taper, rng))
    labels += [None] * n_clutter
    return _stored(t, np.array(times_, dtype=float), np.array(labels, dtype=object), geometry, cfg, rng)


def _clutter_toas(n: int, window_s: float, taper: float, rng: np.random.Generator) -> NDArray[np.float64]:
    """n clutter TOAs on [0, window_s] of density proportional to 1 - taper x / window_s: by
    inversion of its CDF, F(x) = (x - a x^2 / 2) / (1 - a / 2) on x in [0, 1] (a = taper)."""
    if taper == 0.0:
        return rng.uniform(0.0, window_s, n)
    c = rng.uniform(0.0, 1.0, n) * (1.0 - taper / 2.0)
    return window_s * (1.0 - np.sqrt(1.0 - 2.0 * taper * c)) / taper


def _stored(
    t: np.datetime64,
    toa: NDArray[np.float64],
    labels: NDArray[np.object_],
    geometry: Geometry,
    cfg: StressConfig,
    rng: np.random.Generator,
) -> Window:
    """What the float stores of a window's signals: those inside it, rounded, ascending, the
    earliest `max_signals` (nothing, with probability `empty_window_prob`)."""
    arr = np.round(toa, TOA_DECIMALS) + 0.0
    inside = (arr >= 0) & (arr <= geometry.window_s)
    order = np.argsort(arr[inside], kind="stable")
    arr, lab = arr[inside][order], labels[inside][order]
    if rng.random() < cfg.empty_window_prob:
        arr, lab = arr[:0], lab[:0]
    n = min(len(arr), cfg.max_signals)
    return Window(t, arr[:n].copy(), tuple(lab[:n]))


def _events(
    draws: _FloatDraws, beacons: BeaconTable, geometry: Geometry, cfg: StressConfig, gaps: list[list[int]]
) -> dict[str, Any]:
    """What happened to the float (`truth/<float_id>.json`)."""
    ids = np.asarray(beacons.beacon_id, dtype=object)
    truth = draws.truth
    return {
        "geometry": geometry.name,
        "true_sound_speed_m_s": round(float(np.mean(draws.c_beacon)), 2),
        "toa_sd_s": round(float(draws.toa_sd), 3),
        "multipath_fraction": round(float(draws.mp_frac), 4),
        "clutter_rate": cfg.clutter_rate,
        "gaps_days": gaps,
        "outages": [{"beacon": str(ids[i]), "days": [a, b]} for i, a, b in draws.outages],
        "covered_fraction": round(draws.covered, 3),
        "clock_wander_s": round(float(draws.wander_amp), 3),
        "clock_wander": {
            "period_days": round(float(draws.wander_period), 4),
            "phase": round(float(draws.wander_phase), 6),
        },
        "beacons": {
            str(ids[i]): {
                "sound_speed_m_s": round(float(draws.c_beacon[i]), 3),
                "drift_error_s_per_day": round(float(draws.drift_error[i]), 6),
                "p_detect": round(float(draws.p_max[i]), 4),
                "detection_range_km": round(float(draws.r50[i]), 1),
                "falloff_km": round(float(draws.width[i]), 1),
            }
            for i in range(len(beacons))
        },
        "eddies_within_60km_days": int(
            sum(
                any(float(range_m(la, lo, e.lat, e.lon)) < 60e3 for e in draws.eddies)
                for la, lo in zip(truth["lat"][::5], truth["lon"][::5], strict=True)
            )
            * 5
        ),
    }


def _clock_events(clock: tuple[float, float], surfaced: bool, cfg: StressConfig) -> dict[str, Any]:
    """The true clock offsets (launch, end) and whether the float surfaced, when the knobs
    that set them are on (nothing otherwise: the files stay as they were)."""
    if cfg.clock_end_offset_s is None and cfg.never_surfaced_share == 0:
        return {}
    return {"true_clock_offset_s": [round(float(c), 4) for c in clock], "surfaced": surfaced}
