"""`rafostrack legs FLOAT.csv`: a leg model fitted to a float's arrival times.

1. The particle smoother (`run.method.track_record`) tracks the float as `rafostrack track`
   does; the beacons, float and model its final pass used (after calibration: sound
   speed, per-beacon corrections, the float's clock residual, TOA noise, clutter, ...;
   `TrackOutput.problem`) give the windows' likelihood.
2. Each window's ranked-signal log-likelihood (association summed out by the configured
   engine, exact by default) is tabulated on a grid about the smoother's position
   (`evidence`), in a plane about the mission's centre (`plane`); the launch fix and the
   end fix (when used) are Gaussian observations. The float may sit off its legs by an
   independent N(0, s^2 I) per window (eddies shorter than a leg), s sampled too.
3. theta_0: the paper's equal-duration legs through the smoother's positions, ranked by
   the log posterior; then Metropolis-Hastings with local knot and change-time moves,
   the paper's leg moves and reversible jump over K (`sampler`), under the `[legs]` prior.
4. Outputs (`outputs`): legs.parquet, legs_track.parquet (the track schema plus velocity),
   legs.png, legs_run.json.
"""

from __future__ import annotations

import dataclasses
import math
import time
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..config import Config
from ..domain import elapsed_days
from ..errors import InputError
from ..likelihoods import arrivals_from_config
from ..run.method import TrackOutput, track_record
from ..run.one_float import LoadedFloat, TrackInputs, load_float
from .evidence import FloatEvidence, build_grids, float_evidence
from .fit import LegFit
from .model import LegPrior, Legs, log_prior
from .outputs import write_outputs
from .plane import Plane
from .sampler import SamplerConfig, run_chain
from .scores import Measurements
from .theta0 import data_driven_start
from .trajectory import positions

FLOAT_MOVES = {"knot": 4.0, "shift": 1.5, "jump": 2.0, "leg": 0.3, "start": 0.2, "level": 0.2}
WIGGLE_LEVELS = 7  # wiggle sds between 0.5 km and [legs] wiggle_max_km, beside 0


def wiggle_levels(max_km: float) -> tuple[float, ...]:
    """The wiggle sds the sampler chooses among: 0, and WIGGLE_LEVELS from 0.5 km to `max_km`."""
    if max_km <= 0:
        return (0.0,)
    return (0.0, *(round(float(s), 3) for s in np.geomspace(min(0.5, max_km), max_km, WIGGLE_LEVELS)))


THETA0_GUESSES = 16


def leg_prior(config: Config) -> LegPrior:
    c = config.legs
    if c.duration_min_days >= c.duration_max_days:
        raise InputError(
            f"[legs] duration_min_days ({c.duration_min_days}) must be less than duration_max_days "
            f"({c.duration_max_days})"
        )
    return LegPrior(
        speed_mean=c.speed_mean_km_per_day,
        speed_sd=c.speed_sd_km_per_day,
        heading_change_sd_rad=math.radians(c.heading_change_sd_deg),
        duration_min=c.duration_min_days,
        duration_max=c.duration_max_days,
    )


def _centre(lat: NDArray, lon: NDArray) -> Plane:
    ref = float(lon[0])
    unwrapped = ref + (np.asarray(lon) - ref + 180.0) % 360.0 - 180.0
    return Plane(float(np.mean(lat)), float((np.mean(unwrapped) + 180.0) % 360.0 - 180.0))


def fit_legs(
    loaded: LoadedFloat,
    output: TrackOutput,
    rng: np.random.Generator,
) -> LegFit:
    """Steps 2-3 of the module docstring, from the smoother's `output` (the problem its final
    pass tracked, else the loaded one, gives the windows' likelihood)."""
    config, info, record = loaded.problem.config, loaded.problem.info, loaded.record
    if not record.windows:
        raise InputError(f"{record.path}: no listening windows to fit legs to")
    prior = leg_prior(config)
    started = time.perf_counter()
    track = output.track
    plane = _centre(track["lat"].to_numpy(), track["lon"].to_numpy())
    epoch = info.launch_time
    times = np.array([w.time for w in record.windows], dtype="datetime64[ns]")
    window_days = elapsed_days(times, epoch)
    centres = plane.to_plane(track["lat"].to_numpy(), track["lon"].to_numpy())
    tracked = output.problem
    cfg = tracked.tracking_config  # the user's configuration with the calibrated model values
    likelihood = arrivals_from_config(tracked.beacons, tracked.info, cfg)
    grids = build_grids(likelihood, list(record.windows), centres, plane, config.legs.grid_spacing_km,
                        config.legs.grid_half_width_km)  # fmt: skip
    grids_s = time.perf_counter() - started
    launch_xy = plane.to_plane(info.launch_lat, info.launch_lon)
    fixes = [(0.0, launch_xy, config.fixes.launch_sd_km)]
    if info.has_end_fix and config.fixes.use_end_fix:
        end_day = float(elapsed_days(np.array([info.end_time]), epoch)[0])
        fixes.append((end_day, plane.to_plane(info.end_lat, info.end_lon), config.fixes.end_sd_km))
    outside_sd_km = cfg.model.toa_sigma_s * cfg.model.sound_speed_m_s / 1e3
    evidence = float_evidence(window_days, grids, fixes, outside_sd_km, wiggle_levels(config.legs.wiggle_max_km))
    t0, t1 = min(0.0, float(evidence.times[0])), float(evidence.times[-1])
    start = _theta0(evidence, prior, window_days, centres, launch_xy, t0, t1)
    sampler = SamplerConfig(
        iterations=config.legs.iterations,
        moves=FLOAT_MOVES,
        speed_step_var=1.0,
        heading_step_var=0.01,
        duration_proposal=(prior.duration_min, prior.duration_max),
        knot_step=3.0,
        shift_step=1.0,
        start_step=1.0,
        max_legs=max(2, math.ceil((t1 - t0) / prior.duration_min)),
        adapt=True,
    )
    chain = run_chain(evidence, prior, start, sampler, rng, free_start=True)
    timings = {"grids_s": grids_s, "sampler_s": chain.seconds, "fit_s": time.perf_counter() - started}
    return LegFit(info.float_id, epoch, plane, record.windows, window_days, evidence, chain, start, prior, output,
                  timings)  # fmt: skip


def _theta0(evidence: FloatEvidence, prior: LegPrior, window_days: NDArray, centres: NDArray, launch_xy: NDArray,
            t0: float, t1: float) -> Legs:  # fmt: skip
    """The paper's equal-duration legs through the smoother's positions, over counts between
    the prior's shortest and longest legs, ranked by the log posterior."""
    span = t1 - t0
    lo, hi = max(1, math.ceil(span / prior.duration_max)), max(1, math.floor(span / prior.duration_min))
    counts = sorted({round(float(k)) for k in np.geomspace(lo, max(lo, hi), THETA0_GUESSES)})
    data = Measurements(np.concatenate([[0.0], window_days]), np.vstack([launch_xy[None, :], centres]))
    order = np.argsort(data.times, kind="stable")
    data = Measurements(data.times[order], data.xy[order])

    def minus_log_posterior(legs: Legs) -> float:
        lp = log_prior(legs, prior)
        if not math.isfinite(lp):
            return math.inf
        xy = positions(legs, evidence.times)
        return -(lp + float(evidence.terms(xy, slice(0, len(evidence.times)), level=evidence.start_level).sum()))

    return data_driven_start(data, prior, counts, start_time=t0, end_time=t1, objective=minus_log_posterior)


def float_seed(config: Config, float_id: str) -> np.random.Generator:
    """The leg sampler's Generator: the configured seed and the float id."""
    return np.random.default_rng([config.filter.seed, zlib.crc32(float_id.encode()), 11])


@dataclass(frozen=True)
class LegsResult:
    float_id: str
    out_dir: Path
    fit: LegFit
    run: dict[str, Any]


def legs_float(inputs: TrackInputs, out_root: Path, *, plots: bool = True) -> LegsResult:
    """Track the float with the smoother, fit legs, write the outputs (module docstring)."""
    started = time.perf_counter()
    loaded = load_float(inputs)
    config, float_id = loaded.problem.config, loaded.problem.info.float_id
    leg_prior(config)  # a bad [legs] prior fails before the smoother runs
    output = track_record(loaded.problem, loaded.record)
    smoother_s = time.perf_counter() - started
    fit = fit_legs(loaded, output, float_seed(config, float_id))
    fit = dataclasses.replace(fit, timings={"smoother_s": smoother_s, **fit.timings})
    out_dir = Path(out_root) / float_id
    run = write_outputs(fit, loaded, inputs, out_dir, plots=plots, total_s=time.perf_counter() - started)
    return LegsResult(float_id, out_dir, fit, run)
