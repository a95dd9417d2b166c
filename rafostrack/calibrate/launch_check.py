"""A launch fix grossly wrong (a sign typed wrong, the wrong float's row): where do the first
days' arrivals put the float?

The particle filter starts at the launch fix; a fix hundreds of km off (or in the wrong
hemisphere) leaves it where no stored arrival fits, and nothing after it can be calibrated.
Before the first pass, the first `LAUNCH_WINDOWS` windows with arrivals (within
`LAUNCH_DAYS` of the launch) are scored on a grid of `GRID_KM` spacing over every active
source's neighbourhood (`REACH_KM` around each), with the window evidence of the tracker's
own model (association summed out, clutter included; the TOA noise widened by the grid's
spacing and the drift of those days). Their summed log-likelihood at the fix, against the
grid's best,

    log LR = max_x sum_w log p(T_w | x) - sum_w log p(T_w | x_launch),

contradicts the fix when the fix lies beyond `REACH_KM` of every active source (where no
source could be heard), the best lies more than `GROSS_KM` away and log LR exceeds
`[checks] z_score`^2 / 2 (the likelihood-ratio counterpart of z sds); the first pass then
starts at the best node with a launch sd of the grid's spacing, and the Kalman smoother's
own check (`metadata_checks`) refines the position. Errors within the array's reach are left
to that check (which sees a few tens of km; errors of hundreds of km inside the array are
not caught: a first-days grid alone confused clutter with sources on floats that heard
little in their first weeks).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import NDArray

from ..config import with_overrides
from ..domain import ArrivalRecord, BeaconTable, Particles
from ..likelihoods import arrivals_from_config
from ..model.geodesy import displace, range_m
from ..problem import FloatProblem
from .metadata_checks import CONTRADICTED, MetadataCheck, float_source

LAUNCH_WINDOWS = 6
LAUNCH_DAYS = 6.0
GRID_KM = 20.0
REACH_KM = 1200.0
GROSS_KM = 100.0
DRIFT_KM_PER_DAY = 10.0  # how far the float may go in those days, folded into the TOA noise
KM_PER_S = 1.48


def _grid(beacons: BeaconTable, active: NDArray[np.bool_]) -> tuple[NDArray, NDArray]:
    """Nodes every `GRID_KM` within `REACH_KM` of an `active` source."""
    lat0, lon0 = float(np.mean(beacons.lat[active])), float(np.mean(beacons.lon[active]))
    half = REACH_KM + float(range_m(lat0, lon0, beacons.lat[active], beacons.lon[active]).max()) / 1e3
    k = np.arange(-half, half + GRID_KM, GRID_KM)
    east, north = (a.ravel() for a in np.meshgrid(k, k))
    lat, lon = displace(np.full(east.shape, lat0), np.full(east.shape, lon0), east, north)
    near = np.zeros(len(lat), dtype=bool)
    for b_lat, b_lon in zip(beacons.lat[active], beacons.lon[active], strict=True):
        near |= range_m(lat, lon, b_lat, b_lon) <= REACH_KM * 1e3
    return lat[near], lon[near]


def launch_check(problem: FloatProblem, record: ArrivalRecord) -> tuple[MetadataCheck, FloatProblem] | None:
    """The launch fix against the first days' arrivals (module docstring): the check and the
    problem to track (the launch moved where contradicted); None when the fix is within
    reach of a source (`REACH_KM`: left to the Kalman smoother's check) or there are too
    few windows near the launch to tell."""
    info, config = problem.info, problem.config
    end = info.launch_time + np.timedelta64(int(LAUNCH_DAYS * 86400), "s")
    windows = [w for w in record.windows if w.n_signals > 0 and w.time <= end][:LAUNCH_WINDOWS]
    active = problem.beacons.active_at(windows[0].time) if windows else np.zeros(0, dtype=bool)
    if len(windows) < 2 or not active.any():
        return None
    reach_km = float(range_m(info.launch_lat, info.launch_lon, problem.beacons.lat[active],
                             problem.beacons.lon[active]).min()) / 1e3  # fmt: skip
    if reach_km <= REACH_KM:
        return None  # within the array's reach: the Kalman smoother's check weighs it
    lat, lon = _grid(problem.beacons, active)
    lat, lon = np.append(lat, info.launch_lat), np.append(lon, info.launch_lon)
    sigma = float(np.hypot(config.model.toa_sigma_s, (GRID_KM + DRIFT_KM_PER_DAY * LAUNCH_DAYS) / KM_PER_S / 2))
    likelihood = arrivals_from_config(problem.beacons, info, config).with_toa_sigma(sigma)
    particles = Particles(lat, lon, np.zeros((len(lat), 2)))
    loglik = np.sum([likelihood.evaluate(particles, w, marginals=False).loglik for w in windows], axis=0)
    best = int(np.argmax(loglik))
    distance_km = float(range_m(lat[best], lon[best], info.launch_lat, info.launch_lon)) / 1e3
    log_ratio = float(loglik[best] - loglik[-1])
    file, line = float_source(info)
    contradicted = distance_km > GROSS_KM and log_ratio > config.checks.z_score**2 / 2
    check = MetadataCheck(
        file, line, info.float_id, "launch_fix", 0.0, round(distance_km, 1), GRID_KM,
        "km", CONTRADICTED if contradicted else "consistent",
        given_lat_lon=(info.launch_lat, info.launch_lon),
        supported_lat_lon=(round(float(lat[best]), 4), round(float(lon[best]), 4)),
    )  # fmt: skip
    if not contradicted:
        return check, problem
    moved = dataclasses.replace(info, launch_lat=float(lat[best]), launch_lon=float(lon[best]))
    tracked = FloatProblem(problem.beacons, moved, with_overrides(config, fixes={"launch_sd_km": GRID_KM}))
    return dataclasses.replace(check, used=check.supported), tracked
