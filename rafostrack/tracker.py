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
    """Filter the record with the float's own generator, then smooth if configured."""
    want_filtered = not config.smoother.enabled or also_filtered
    pf = ParticleFilter(beacons, info, config, label_probs=want_filtered)
    started = time.perf_counter()
    run = pf.run(record, float_rng(config.filter.seed, info.float_id))
    filter_s = time.perf_counter() - started
    filtered = None
    if want_filtered:
        filtered = build_estimate(run, pf, beacons, config.ambiguity)
    smoother_s = 0.0
    estimate = filtered
    if config.smoother.enabled:
        started = time.perf_counter()
        weights = smooth([s.cloud for s in run.steps], config.motion.diffusion_km_per_day)
        estimate = build_estimate(run, pf, beacons, config.ambiguity, weights)
        smoother_s = time.perf_counter() - started
    return TrackOutput(estimate, filtered, run.n_resamples, run.warnings, filter_s, smoother_s)
