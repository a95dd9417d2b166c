"""The smoother: against an exact Kalman (RTS) smoother, on ambiguity, and on calibration."""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest
from support import CLOCKED_CASES, LINEAR_GAUSSIAN_CASES, rts_smoother

from rafostrack.config import load_config, with_overrides
from rafostrack.domain import BeaconTable, Cloud, FloatInfo, Particles
from rafostrack.filtering.resampling import normalise_log_weights, systematic
from rafostrack.model.geodesy import displace, local_offsets_km, range_m
from rafostrack.motion import MOTION_MODELS, ClockWalk
from rafostrack.problem import FloatProblem
from rafostrack.run.method import track_record
from rafostrack.sim.evaluate import inside_ellipse, position_errors_km, true_labels
from rafostrack.sim.scenarios import synthetic_scenario
from rafostrack.sim.simulate import simulate_arrivals, simulate_mission
from rafostrack.smoothing.ffbsm import smooth
from rafostrack.summaries.posterior import ELLIPSE_95_SCALE, summarise

LAT0, LON0 = -58.0, -90.0
T0 = np.datetime64("2010-01-01T00:00", "ns")
DAY = np.timedelta64(1, "D")
NAT = np.datetime64("NaT", "ns")


@pytest.mark.parametrize("max_columns", [3000, 1000], ids=["all-particles", "1000-columns"])
@pytest.mark.parametrize("name", [*sorted(MOTION_MODELS), *CLOCKED_CASES])
def test_smoothed_marginals_match_the_exact_rts_smoother(name, max_columns):
    """Every motion model, observed by noisy position fixes, is a linear-Gaussian model,
    whose exact smoothed marginals the Kalman/RTS recursions give. FFBSm on a bootstrap
    filter's clouds must reproduce them within Monte Carlo error, and differ clearly from
    the filter; so must FFBSm on 1000 quantile points of each 3000-particle cloud. The
    filter moves particles in a plane with the model's own A, b, L; the smoother sees them
    on the ellipsoid, as it does in tracking. With the float clock in the state, the clock
    is observed too, through the east position (a common shift of the arrivals, y = clock
    + east / 1.5), and its smoothed mean and sd must match as well."""
    motion = {**LINEAR_GAUSSIAN_CASES, **CLOCKED_CASES}[name]
    tr = motion.components(1.0)[0][1]  # the whole state's kernel (the clock's block last)
    d = tr.dim
    clocked = isinstance(motion, ClockWalk)
    # Seed 12 for the clock: at 11 this bootstrap filter (not the smoother) collapses at step
    # 23 (ESS 16 of 3000), and the smoother starts from that step (clock seeds 12-15: RMS
    # 0.14-0.20, max 0.56).
    rng = np.random.default_rng(12 if clocked else 11)
    n, steps, r = 3000, 25, 4.0**2
    h = np.eye(2, d)
    if clocked:
        h = np.vstack([h, np.eye(1, d, d - 1) + np.eye(1, d, 0) / 1.5])
    m0 = np.zeros(d)
    p0 = np.eye(d)
    if motion.has_velocity:
        m0[2:4], p0[2:4, 2:4] = motion.stationary_velocity()[0], motion.stationary_velocity()[1] ** 2 * np.eye(2)
    truth = np.empty((steps, d))
    x = m0 + np.linalg.cholesky(p0) @ rng.standard_normal(d)
    for t in range(steps):
        x = tr.A @ x + tr.b + tr.L @ rng.standard_normal(d)
        truth[t] = x
    y = truth @ h.T + rng.normal(0, np.sqrt(r), (steps, len(h)))
    states = m0[:, None] + np.linalg.cholesky(p0) @ rng.standard_normal((d, n))
    clouds, filt_means = [], []
    for t in range(steps):
        states = tr.A @ states + tr.b[:, None] + tr.L @ rng.standard_normal((d, n))
        residual = y[t][:, None] - h @ states
        log_w = -np.einsum("kp,kp->p", residual, residual) / (2 * r)
        w, _ = normalise_log_weights(log_w)
        lat, lon = displace(np.full(n, LAT0), np.full(n, LON0), states[0], states[1])
        velocity = states[2:4].T.copy() if motion.has_velocity else None
        clouds.append(Cloud(T0 + t * DAY, Particles(lat, lon, velocity, states[-1].copy() if clocked else None), w))
        filt_means.append(states[:2] @ w)
        states = states[:, systematic(w, rng)]
    smoothed = smooth(clouds, motion, max_columns=max_columns).weights
    assert all(np.count_nonzero(w) <= max_columns for w in smoothed)
    m_s, p_s = rts_smoother(y, tr, h, r, m0, p0)
    z, z_filter, sd_ratio = [], [], []  # errors in units of the exact smoothed sd, per axis and time
    for t, (cloud, w) in enumerate(zip(clouds, smoothed, strict=True)):
        s = summarise(cloud.lat, cloud.lon, w)
        est = np.array(local_offsets_km(s.lat, s.lon, LAT0, LON0), dtype=float)
        sd = np.sqrt(np.diag(p_s[t])[:2])
        z.extend((est - m_s[t, :2]) / sd)
        z_filter.extend((filt_means[t] - m_s[t, :2]) / sd)
        sd_ratio.extend(np.sqrt(np.diag(s.cov_km2)) / sd)
        if clocked:
            w_all = w / w.sum()
            clock_mean = float(w_all @ cloud.particles.clock_s)
            clock_sd = float(np.sqrt(w_all @ (cloud.particles.clock_s - clock_mean) ** 2))
            z.append((clock_mean - m_s[t, -1]) / np.sqrt(p_s[t, -1, -1]))
            sd_ratio.append(clock_sd / np.sqrt(p_s[t, -1, -1]))
    z, z_filter, sd_ratio = np.array(z), np.array(z_filter), np.array(sd_ratio)
    # Monte Carlo error of 3000 particles (seeds 11-15: RMS 0.03-0.15, max 0.49).
    assert np.sqrt(np.mean(z**2)) < 0.25 and np.abs(z).max() < 0.75
    assert np.sqrt(np.mean((sd_ratio - 1) ** 2)) < 0.12 and np.abs(sd_ratio - 1).max() < 0.35
    assert np.sqrt(np.mean(z_filter**2)) > 0.4  # the test can tell the smoother from the filter


def test_smoothing_improves_on_filtering_and_is_calibrated():
    """Clutter 1: smoothed labels >= 98.5% right, and their probabilities calibrated: the
    expected number of wrong labels, sum(1 - prob), matches the count (within a Poisson
    margin), and confident labels (prob >= 0.99) are almost never wrong. (A clutter signal
    within ~sigma of a missed beacon's predicted arrival is rightly called that beacon with
    probability ~0.999: such a label is wrong with about that small probability, not never.)
    RMSE clearly below the filter's; the 95% ellipse holds the truth in a band around 95%
    (loose: a small mission)."""
    config = with_overrides(load_config(), filter={"particles": 800})
    beacons, floats = synthetic_scenario(days=90, rng=3, n_floats=2)
    clean = dataclasses.replace(config.model, multipath_fraction=0.0, echo_fraction=0.0)  # one arrival per source
    mission = simulate_mission(beacons, floats, clean, np.random.default_rng(3))
    rmse = {"filtered": [], "smoothed": []}
    covered, right, prob = [], [], []
    for sim in mission.floats:
        out = track_record(FloatProblem(beacons, sim.info, config), sim.record, also_filtered=True)
        for est in (out.filtered, out.estimate):
            rmse[est.kind].append(np.sqrt(np.mean(position_errors_km(est.track, sim.truth) ** 2)))
        covered.extend(inside_ellipse(out.estimate.track, sim.truth, ELLIPSE_95_SCALE))
        estimated = [b if isinstance(b, str) else None for b in out.estimate.labels["beacon_id"]]
        right.extend(a == b for a, b in zip(estimated, true_labels(sim.record), strict=True))
        prob.extend(out.estimate.labels["prob"].to_numpy())
    right, prob = np.array(right), np.array(prob)
    assert np.mean(rmse["smoothed"]) < 0.85 * np.mean(rmse["filtered"])
    assert np.mean(right) >= 0.985
    expected_wrong, wrong = float(np.sum(1.0 - prob)), int(np.sum(~right))
    assert abs(wrong - expected_wrong) <= 3.0 * np.sqrt(expected_wrong) + 2.0
    confident = prob >= 0.99
    assert np.mean(~right[confident]) < 0.005
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
    # A random walk, and no calibration: with a velocity-persistent drift model, learnt or
    # not, the float's steady 3 km/day northwards over the first 20 days rules out its mirror
    # image's U-turn at the line (the mirror mode then dies, rightly). Here the arrival
    # times alone must decide, and they cannot.
    config = with_overrides(
        load_config(),
        model={"clutter_rate": 0.5},
        filter={"particles": 2000, "seed": 1},
        calibrate={"enabled": False},
        motion={"model": "random_walk"},
    )
    model = dataclasses.replace(config.model, p_detect=0.999999)  # simulate: every source heard
    record, _ = simulate_arrivals(beacons, info, model, truth, np.random.default_rng(5), days=40)
    out = track_record(FloatProblem(beacons, info, config), record)
    track = out.track.set_index("time")
    day = (track.index - pd.Timestamp(T0)).days
    assert not track["ambiguous"][day <= 18].any()  # three or four clean signals
    late = track[day >= 28]  # mirror images >= 48 km apart
    assert late["ambiguous"].mean() >= 0.8
    assert (late.loc[late["ambiguous"], "second_mode_km"] > 30).all()  # where flagged: the mirror pair
    modes = out.estimate.modes.set_index("time")
    flagged = late.index[late["ambiguous"]]
    for t, row in truth.set_index("time").loc[flagged].iterrows():
        m = modes.loc[[t]]
        # The truth is in one of the two modes: within 3 of that mode's sds (two ranges
        # crossing at ~20 degrees fix the north-south position only to ~15 km).
        distance = range_m(row.lat, row.lon, m["lat"].to_numpy(), m["lon"].to_numpy()) / 1e3
        assert np.min(distance / m["sd_km"].to_numpy()) < 3.0
