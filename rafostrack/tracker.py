"""Track one float's record in memory: filter, smooth (unless disabled), summarise.

This is the whole method without any file I/O; `pipeline` reads inputs and writes outputs
around it, and tests, benchmarks and experiments call it directly.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

from .config import Config
from .estimates import Estimate, build_estimate
from .filter import ParticleFilter, float_rng
from .inputs import ArrivalRecord, BeaconTable, FloatInfo
from .smoother import smooth


@dataclass(frozen=True)
class TrackOutput:
    estimate: Estimate  # smoothed when the smoother is enabled, else filtered
    filtered: Estimate | None  # the filtered estimate, when asked for (or when it is the estimate)
    n_resamples: int
    warnings: list[str]  # recoverable problems met while filtering
    filter_s: float
    smoother_s: float

    @property
    def track(self):
        return self.estimate.track

    @property
    def labels(self):
        return self.estimate.labels


def track_record(
    beacons: BeaconTable, info: FloatInfo, config: Config, record: ArrivalRecord, *, also_filtered: bool = False
) -> TrackOutput:
    """Filter the record with the float's own generator, then smooth if configured.

    Without smoothing, each step is summarised as the filter makes it and then dropped, so
    memory does not grow with the record; smoothing needs every step's cloud (about
    24 bytes per particle per window)."""
    rng = float_rng(config.filter.seed, info.float_id)
    started = time.perf_counter()
    if not config.smoother.enabled:  # no history needed: summarise each step as it is made
        pf = ParticleFilter(beacons, info, config)
        filtered = build_estimate(info.float_id, pf.steps(record, rng), pf, beacons, config.ambiguity)
        filter_s = time.perf_counter() - started
        return TrackOutput(filtered, filtered, pf.n_resamples, list(pf.warnings), filter_s, 0.0)

    pf = ParticleFilter(beacons, info, config, label_probs=also_filtered)
    run = pf.run(record, rng)
    filter_s = time.perf_counter() - started
    filtered = build_estimate(info.float_id, run.steps, pf, beacons, config.ambiguity) if also_filtered else None
    started = time.perf_counter()
    weights = smooth([s.cloud for s in run.steps], config.motion.diffusion_km_per_day)
    estimate = build_estimate(info.float_id, run.steps, pf, beacons, config.ambiguity, weights)
    smoother_s = time.perf_counter() - started
    return TrackOutput(estimate, filtered, run.n_resamples, run.warnings, filter_s, smoother_s)
