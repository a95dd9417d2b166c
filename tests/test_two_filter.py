"""The two-filter smoother: against the exact Kalman (RTS) smoother, and where the forward
filter lost the float."""

from __future__ import annotations

import numpy as np
import pytest
from support import LINEAR_GAUSSIAN_CASES, rts_smoother

from rafostrack.domain import Cloud, Particles
from rafostrack.filtering.resampling import normalise_log_weights, systematic
from rafostrack.model.geodesy import displace, local_offsets_km
from rafostrack.motion import MOTION_MODELS, JumpMixture, MotionModel, RandomWalk
from rafostrack.smoothing.ffbsm import smooth
from rafostrack.smoothing.two_filter import forward_view, two_filter_smooth
from rafostrack.summaries.posterior import summarise

LAT0, LON0 = -58.0, -90.0
T0 = np.datetime64("2010-01-01T00:00", "ns")
DAY = np.timedelta64(1, "D")
R_KM2 = 4.0**2  # position fixes, sd 4 km per axis


def _cloud(t: int, states: np.ndarray, weights: np.ndarray) -> Cloud:
    """Planar states (d, n) about (LAT0, LON0) as a cloud on the ellipsoid at day t."""
    lat, lon = displace(np.full(states.shape[1], LAT0), np.full(states.shape[1], LON0), states[0], states[1])
    velocity = states[2:].T.copy() if len(states) > 2 else None
    return Cloud(T0 + t * DAY, Particles(lat, lon, velocity), weights)


def _bootstrap(
    motion: MotionModel, start: np.ndarray, fixes: np.ndarray, days: list[int], rng: np.random.Generator, lost=None
) -> tuple[list[Cloud], list[float]]:
    """A bootstrap filter in the plane over position fixes at `days` from the states
    `start` (d, n); its clouds and step log evidences. `lost = (k, offset)`: at step k the
    particles are proposed from the drift shifted by `offset` km east and weighted
    correctly for it (a filter that puts its particles in the wrong place: normalised,
    its weights look like any others, only its evidence is low)."""
    tr = motion.transition(1.0)
    n = start.shape[1]
    states, log_w = start, np.zeros(n)
    clouds, evidence = [], []
    for k, (y, day) in enumerate(zip(fixes, days, strict=True)):
        noise = tr.L @ rng.standard_normal((tr.dim, n))
        mean = tr.A @ states + tr.b[:, None]
        states = mean + noise
        log_q = np.zeros(n)
        if lost is not None and k == lost[0]:
            states[0] += lost[1]
            white = np.linalg.inv(tr.L)
            z_f = white @ (states - mean)
            z_q = white @ noise  # log f - log q: the drift's density over the shifted proposal's
            log_q = -0.5 * np.einsum("dp,dp->p", z_f, z_f) + 0.5 * np.einsum("dp,dp->p", z_q, z_q)
        _, log_prior = normalise_log_weights(log_w)
        log_w = log_w - ((states[0] - y[0]) ** 2 + (states[1] - y[1]) ** 2) / (2 * R_KM2) - np.log(2 * np.pi * R_KM2)
        log_w = log_w + log_q
        w, log_post = normalise_log_weights(log_w)
        clouds.append(_cloud(day, states, w))
        evidence.append(log_post - log_prior)
        states, log_w = states[:, systematic(w, rng)], np.zeros(n)
    return clouds, evidence


def _both_filters(motion: MotionModel, steps: int, n: int, seed: int, lost=None):
    """Truth, fixes and both filters' clouds for a float launched at day 0 (prior N(m0, p0)),
    fixed at days 1..steps (the windows) and steps + 1 (the end fix)."""
    tr = motion.transition(1.0)
    d = tr.dim
    rng = np.random.default_rng(seed)
    m0, p0 = np.zeros(d), np.eye(d)
    if motion.has_velocity:
        mean, sd = motion.stationary_velocity()
        m0[2:], p0[2:, 2:] = mean, sd**2 * np.eye(2)
    x = m0 + np.linalg.cholesky(p0) @ rng.standard_normal(d)
    truth = []
    for _ in range(steps + 1):
        x = tr.A @ x + tr.b + tr.L @ rng.standard_normal(d)
        truth.append(x)
    truth = np.array(truth)
    fixes = truth[:, :2] + rng.normal(0, np.sqrt(R_KM2), (steps + 1, 2))
    start = m0[:, None] + np.linalg.cholesky(p0) @ rng.standard_normal((d, n))
    forward, forward_ev = _bootstrap(motion, start, fixes[:-1], list(range(1, steps + 1)), rng, lost)
    # The backward filter: from gamma x N(end fix) (flat in position, stationary velocity),
    # moved by the reversed drift (velocities negated) back over the windows.
    back = motion.reversed()
    end = np.zeros((d, n))
    end[:2] = fixes[-1][:, None] + rng.normal(0, np.sqrt(R_KM2), (2, n))
    if motion.has_velocity:
        mean, sd = back.stationary_velocity()
        end[2:] = mean[:, None] + sd * rng.standard_normal((2, n))
    backward, backward_ev = _bootstrap(back, end, fixes[-2::-1], list(range(steps, 0, -1)), rng)
    prior = [_cloud(0, start, np.full(n, 1.0 / n)), *forward]
    end_cloud = _cloud(steps + 1, end, np.full(n, 1.0 / n))
    return truth, fixes, prior, forward_ev, forward_view([end_cloud, *backward]), backward_ev[::-1], (m0, p0)


def _means_km(clouds: list[Cloud], weights: list[np.ndarray]) -> np.ndarray:
    out = []
    for cloud, w in zip(clouds, weights, strict=True):
        s = summarise(cloud.lat, cloud.lon, w)
        out.append(local_offsets_km(s.lat, s.lon, LAT0, LON0))
    return np.array(out, dtype=float)


@pytest.mark.parametrize("name", sorted(MOTION_MODELS))
def test_two_filter_marginals_match_the_exact_rts_smoother(name):
    """Every motion model, observed by noisy position fixes, is linear-Gaussian: the two
    filters joined must reproduce the exact smoothed means and sds (Kalman/RTS, the end
    fix one more observation) within Monte Carlo error, and differ clearly from the
    forward filter's."""
    motion = LINEAR_GAUSSIAN_CASES[name]
    steps, n = 25, 3000
    _, fixes, forward, f_ev, backward, b_ev, (m0, p0) = _both_filters(motion, steps, n, seed=11)
    clouds, smoothed = two_filter_smooth(forward, f_ev, backward, b_ev, motion)
    tr = motion.transition(1.0)
    m_s, p_s = rts_smoother(fixes, tr, np.eye(2, tr.dim), R_KM2, m0, p0)
    est = _means_km(clouds, smoothed.weights)
    filt = _means_km(forward[1:], [c.weights for c in forward[1:]])
    sd = np.sqrt(np.stack([np.diag(p)[:2] for p in p_s[:steps]]))
    z = (est - m_s[:steps, :2]) / sd
    z_filter = (filt - m_s[:steps, :2]) / sd
    sd_est = np.array(
        [np.sqrt(np.diag(summarise(c.lat, c.lon, w).cov_km2)) for c, w in zip(clouds, smoothed.weights, strict=True)]
    )
    sd_ratio = np.sqrt(sd_est**2 + np.array([np.diag(k) for k in smoothed.kernel_cov_km2])) / sd
    # Monte Carlo error of 3000 particles per filter, each joined on JOIN_COLUMNS quantile points.
    assert np.sqrt(np.mean(z**2)) < 0.25 and np.abs(z).max() < 0.75
    assert np.sqrt(np.mean((sd_ratio - 1) ** 2)) < 0.15 and np.abs(sd_ratio - 1).max() < 0.35
    assert np.sqrt(np.mean(z_filter**2)) > 0.4  # the test can tell the smoother from the filter


def test_a_stretch_the_forward_filter_lost_is_taken_from_the_backward_filter():
    """At window 12 the forward filter puts its particles 40 km east of where the data put
    the float (weighted correctly, so only its evidence shows it). FFBSm can only reweight
    those particles and stays 40 km off; joined with the backward filter the estimate there
    is where the exact smoother has it.

    (Joined by each filter's own step evidence, a lost filter's particles lose: its
    evidence there is low. Pooled by the balance heuristic instead, the lost filter's
    evidence would enter the other filter's weights: seeds 0-4 put that window 0.5-2.7 sd
    off.)"""
    motion = JumpMixture(RandomWalk(5.0), 0.01, 100.0)
    steps, n, lost = 24, 1000, 11
    _, fixes, forward, f_ev, backward, b_ev, (m0, p0) = _both_filters(motion, steps, n, seed=5, lost=(lost, 40.0))
    base = motion.transition(1.0)
    m_s, p_s = rts_smoother(fixes, base, np.eye(2), R_KM2, m0, p0)
    sd = np.sqrt(np.stack([np.diag(p)[:2] for p in p_s[:steps]]))
    clouds, smoothed = two_filter_smooth(forward, f_ev, backward, b_ev, motion)
    joined = (_means_km(clouds, smoothed.weights) - m_s[:steps, :2]) / sd
    ffbsm = _means_km(forward[1:], smooth(forward[1:], motion).weights) - m_s[:steps, :2]
    assert np.abs(ffbsm[lost, 0]) > 15.0  # FFBSm cannot leave the lost particles (sd ~2.5 km)
    assert np.abs(joined[lost]).max() < 0.5
    # The windows just after it are still partly lost by the forward filter; joined with
    # the backward filter they stay within 2.5 sd (seeds 0-4: 0.3-2.4), the rest within Monte
    # Carlo error.
    assert np.abs(joined).max() < 2.5 and np.sqrt(np.mean(joined**2)) < 0.5


def test_each_window_is_joined_on_its_own():
    """Joined in two parts (as `rafostrack track` joins them in two processes), the windows
    are the same bits as joined together."""
    motion = LINEAR_GAUSSIAN_CASES[sorted(MOTION_MODELS)[0]]
    _, _, forward, f_ev, backward, b_ev, _ = _both_filters(motion, 9, 300, seed=3)
    whole_clouds, whole = two_filter_smooth(forward, f_ev, backward, b_ev, motion)
    parts = [two_filter_smooth(forward, f_ev, backward, b_ev, motion, windows=w) for w in (range(4), range(4, 9))]
    clouds = [c for part_clouds, _ in parts for c in part_clouds]
    assert len(clouds) == len(whole_clouds) == 9
    for a, b in zip(clouds, whole_clouds, strict=True):
        np.testing.assert_array_equal(a.weights, b.weights)
        np.testing.assert_array_equal(a.lat, b.lat)
    kernels = [k for _, part in parts for k in part.kernel_cov_km2]
    np.testing.assert_array_equal(np.array(kernels), np.array(whole.kernel_cov_km2))
