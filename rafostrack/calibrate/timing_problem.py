"""The timing fit's problem: a first pass's confident labels as the batch Kalman smoother's
arrivals, and what is done with the fit (sources left out, the corrected beacon table)."""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import NDArray

from ..config import Config
from ..domain import ArrivalRecord, BeaconTable, FloatInfo, elapsed_days
from ..model.geodesy import displace
from ..summaries.estimates import Estimate
from . import kalman

MIN_ARRIVALS = 60  # fewer confident arrivals than this: no calibration
# A source heard on at most this many confident arrivals is left out of the calibration
# when leaving it out moves the shared sound speed by more than the speed's posterior sd
# (`hinging_sources`).
LOW_SUPPORT_ARRIVALS = 2
CONFIDENT_PROB = 0.9


def timing_problem(
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
        clock_sd_s=(config.fixes.clock_offset_sd_s, config.fixes.clock_offset_sd_s if info.has_end_clock else None),
    )
    return problem, heard, mid


def hinging_sources(problem: kalman.Problem, fit: kalman.KalmanFit, priors: kalman.KalmanPriors) -> NDArray[np.bool_]:
    """(H,) the heard sources the shared sound speed hinges on without support: at most
    `LOW_SUPPORT_ARRIVALS` confident arrivals, and leaving them out moves the fitted speed
    by more than its posterior sd. The speed is weakly identified (source offsets trade
    against it), so one arrival of a far source, heard nowhere else in the record, can move
    it by several m/s; such an arrival is most often clutter that fell near the source's
    predicted time (a source heard once is, by the record's own evidence, not heard there)."""
    shift, sd = kalman.sound_speed_influence(problem, fit, priors)
    counts = np.bincount(problem.beacon, minlength=problem.n_heard)
    return (counts <= LOW_SUPPORT_ARRIVALS) & (np.abs(shift) > sd)


def without_sources(
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
        released=None if problem.released is None else problem.released[~drop],
        released_positions=None if problem.released_positions is None else problem.released_positions[~drop],
    ), mid[~drop]


def track_at(
    record: ArrivalRecord, node_time: NDArray[np.datetime64], lat: NDArray, lon: NDArray
) -> tuple[NDArray, NDArray]:
    """Positions at every window of `record`, linear in time between the smoother's nodes."""
    t = np.array([w.time for w in record.windows], dtype="datetime64[ns]").astype(np.int64).astype(float)
    nodes = node_time.astype("datetime64[ns]").astype(np.int64).astype(float)
    unwrapped = np.degrees(np.unwrap(np.radians(lon)))
    return np.interp(t, nodes, lat), (np.interp(t, nodes, unwrapped) + 180.0) % 360.0 - 180.0


def corrected_beacons(
    beacons: BeaconTable, heard: NDArray[np.intp], fit: kalman.KalmanFit, speeds_fitted: bool
) -> BeaconTable:
    """The beacon table with the fitted offset and drift corrections, the fitted positions of
    sources the fit moved, and the fitted sound speeds when `speeds_fitted` (not when the
    user set the sound speed)."""
    offset, drift = beacons.offset_s.copy(), beacons.drift_s_per_day.copy()
    offset[heard] += fit.offset_s
    drift[heard] += fit.drift_s_per_day
    if np.any(fit.source_shift_km):
        lat, lon = displace(
            beacons.lat[heard], beacons.lon[heard], fit.source_shift_km[:, 0], fit.source_shift_km[:, 1]
        )
        beacons = dataclasses.replace(beacons, lat=_put(beacons.lat, heard, lat), lon=_put(beacons.lon, heard, lon))
    if not speeds_fitted:
        return dataclasses.replace(beacons, offset_s=offset, drift_s_per_day=drift)
    speeds = np.full(len(beacons), np.nan) if beacons.sound_speed_m_s is None else beacons.sound_speed_m_s.copy()
    speeds[heard] = fit.beacon_sound_speed_m_s
    return dataclasses.replace(beacons, offset_s=offset, drift_s_per_day=drift, sound_speed_m_s=speeds)


def _put(values: NDArray, rows: NDArray[np.intp], new: NDArray) -> NDArray:
    """A copy of `values` with `new` at `rows`."""
    out = values.copy()
    out[rows] = new
    return out
