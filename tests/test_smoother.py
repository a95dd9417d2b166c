"""The smoother: against an exact Kalman (RTS) smoother, on ambiguity, and on calibration."""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest

from rafostrack.config import load_config, with_overrides
from rafostrack.evaluate import inside_ellipse, position_errors_km, true_labels
from rafostrack.geodesy import displace, local_offsets_km, range_m
from rafostrack.inputs import BeaconTable, FloatInfo
from rafostrack.posterior import ELLIPSE_95_SCALE, summarise
from rafostrack.resampling import normalise_log_weights, systematic
from rafostrack.simulate import simulate_arrivals, simulate_mission, synthetic_scenario
from rafostrack.smoother import Cloud, smooth
from rafostrack.tracker import track_record

LAT0, LON0 = -58.0, -90.0
T0 = np.datetime64("2010-01-01T00:00", "ns")
DAY = np.timedelta64(1, "D")
NAT = np.datetime64("NaT", "ns")


def _rts_random_walk(y: np.ndarray, q: float, r: float, p0: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact smoothed mean and variance of x_t = x_{t-1} + N(0, q), y_t = x_t + N(0, r), x_0 ~ N(0, p0)."""
    n = len(y)
    m_f, p_f = np.empty(n), np.empty(n)
    m, p = 0.0, p0
    for t in range(n):
        p_pred = p + q
        gain = p_pred / (p_pred + r)
        m, p = m + gain * (y[t] - m), (1 - gain) * p_pred
        m_f[t], p_f[t] = m, p
    m_s, p_s = m_f.copy(), p_f.copy()
    for t in range(n - 2, -1, -1):
        c = p_f[t] / (p_f[t] + q)
        m_s[t] = m_f[t] + c * (m_s[t + 1] - m_f[t])
        p_s[t] = p_f[t] + c * c * (p_s[t + 1] - p_f[t] - q)
    return m_s, p_s


def test_smoothed_marginals_match_the_rts_smoother():
    """Random walk observed by noisy position fixes: a linear-Gaussian model, whose exact
    smoothed marginals the RTS recursions give. FFBSm on a bootstrap filter's clouds must
    reproduce them within Monte Carlo error, and differ clearly from the filter."""
    rng = np.random.default_rng(11)
    n, steps, d, r = 3000, 25, 5.0, 4.0**2
    truth = np.cumsum(rng.normal(0, d, (steps, 2)), axis=0)
    y = truth + rng.normal(0, np.sqrt(r), (steps, 2))
    east, north = rng.normal(0, 1.0, (2, n))
    clouds, filt_means = [], []
    for t in range(steps):
        east, north = east + rng.normal(0, d, n), north + rng.normal(0, d, n)
        log_w = -((east - y[t, 0]) ** 2 + (north - y[t, 1]) ** 2) / (2 * r)
        w, _ = normalise_log_weights(log_w)
        lat, lon = displace(np.full(n, LAT0), np.full(n, LON0), east, north)
        clouds.append(Cloud(T0 + t * DAY, lat, lon, w))
        filt_means.append([w @ east, w @ north])
        idx = systematic(w, rng)
        east, north = east[idx], north[idx]
    smoothed = smooth(clouds, diffusion_km_per_day=d)
    worst_gap_filter = 0.0
    for axis in range(2):
        m_s, p_s = _rts_random_walk(y[:, axis], d * d, r, 1.0)
        for t, (cloud, w) in enumerate(zip(clouds, smoothed, strict=True)):
            s = summarise(cloud.lat, cloud.lon, w)
            e, nn = local_offsets_km(s.lat, s.lon, LAT0, LON0)
            est = float([e, nn][axis])
            assert est == pytest.approx(m_s[t], abs=0.6)
            assert np.sqrt(s.cov_km2[axis, axis]) == pytest.approx(np.sqrt(p_s[t]), rel=0.25)
            worst_gap_filter = max(worst_gap_filter, abs(filt_means[t][axis] - m_s[t]))
    assert worst_gap_filter > 1.5  # the test can tell the smoother from the filter


def test_smoothing_improves_on_filtering_and_is_calibrated():
    """Clutter 1: smoothed labels >= 98.5% right, the wrong ones reported as doubtful
    (near-ties of two beacons within ~sigma), RMSE clearly below the filter's, and the 95%
    ellipse holds the truth in a band around 95% (loose: a small mission)."""
    config = with_overrides(load_config(), filter={"particles": 800})
    beacons, floats = synthetic_scenario(days=90, rng=3, n_floats=2)
    mission = simulate_mission(beacons, floats, config.model, np.random.default_rng(3))
    rmse = {"filtered": [], "smoothed": []}
    covered, right, wrong_prob = [], [], []
    for sim in mission.floats:
        out = track_record(beacons, sim.info, config, sim.record, also_filtered=True)
        for est in (out.filtered, out.estimate):
            rmse[est.kind].append(np.sqrt(np.mean(position_errors_km(est.track, sim.truth) ** 2)))
        covered.extend(inside_ellipse(out.estimate.track, sim.truth, ELLIPSE_95_SCALE))
        estimated = [b if isinstance(b, str) else None for b in out.estimate.labels["beacon_id"]]
        ok = np.array([a == b for a, b in zip(estimated, true_labels(sim.record), strict=True)])
        right.extend(ok)
        wrong_prob.extend(out.estimate.labels["prob"].to_numpy()[~ok])
    assert np.mean(rmse["smoothed"]) < 0.85 * np.mean(rmse["filtered"])
    assert np.mean(right) >= 0.985
    assert max(wrong_prob, default=0.0) < 0.9
    assert 0.85 <= np.mean(covered) <= 0.995


def _two_beacon_stretch():
    """Beacons A, B east and west of the float; C, D north and south, silent after day 20.
    The float drifts north across the A-B line at day 20; from then on only A and B are
    heard, so its mirror image across that line fits the data equally well."""
    beacons = BeaconTable(
        beacon_id=np.array(["A", "B", "C", "D"], dtype=object),
        lat=np.array([LAT0, LAT0, LAT0 + 2.5, LAT0 - 2.5]),
        lon=np.array([LON0 - 5.0, LON0 + 5.0, LON0, LON0]),
        offset_s=np.array([0.0, 600.0, 1200.0, 1800.0]),
        drift_s_per_day=np.zeros(4),
        start=np.full(4, NAT),
        end=np.array([NAT, NAT, T0 + 20 * DAY, T0 + 20 * DAY]),
    )
    grid = LAT0 + np.linspace(-0.5, 0.1, 6001)  # the A-B geodesic's latitude at LON0
    on_line = grid[np.argmin(range_m(grid, LON0, LAT0, LON0 - 5.0) + range_m(grid, LON0, LAT0, LON0 + 5.0))]
    days = np.arange(0, 41)
    lat, lon = displace(np.full(41, on_line), np.full(41, LON0), np.zeros(41), 3.0 * (days - 20.0))
    truth = pd.DataFrame({"time": T0 + days * DAY, "lat": lat, "lon": lon})
    info = FloatInfo("f2", T0, lat[0], lon[0], NAT, np.nan, np.nan, 0.0, 0.0, 4200.0, 4)
    return beacons, info, truth


def test_two_beacon_stretch_is_flagged_ambiguous():
    beacons, info, truth = _two_beacon_stretch()
    config = with_overrides(load_config(), model={"clutter_rate": 0.5}, filter={"particles": 2000, "seed": 1})
    model = dataclasses.replace(config.model, p_detect=0.999999)  # simulate: every source heard
    record, _ = simulate_arrivals(beacons, info, model, truth, np.random.default_rng(5), days=40)
    out = track_record(beacons, info, config, record)
    track = out.track.set_index("time")
    day = (track.index - pd.Timestamp(T0)).days
    assert not track["ambiguous"][day <= 18].any()  # three or four clean signals
    late = track[day >= 28]  # mirror images >= 48 km apart
    assert late["ambiguous"].mean() >= 0.8
    assert (late["second_mode_km"] > 30).all()
    modes = out.estimate.modes.set_index("time")
    for t, row in truth.set_index("time").loc[late.index].iterrows():
        m = modes.loc[[t]]
        nearest = range_m(row.lat, row.lon, m["lat"].to_numpy(), m["lon"].to_numpy()).min() / 1e3
        assert nearest < 10.0
