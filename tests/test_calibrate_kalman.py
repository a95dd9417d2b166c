"""calibrate.kalman: the batch smoother in information form against a dense Gaussian built
here from the model's generative description (the oracle), and on a simulated float whose
timing nuisances are known.

The oracle writes every unknown as mean + M z, z iid standard normal, by running the
model's recursions forward (statics, the launch state, then per interval the exact OU
transition and the clock's integrated random walk, their moments from the closed forms),
and the arrivals as linear in the unknowns at the linearisation point (position
derivatives by finite differences of range_m, the rest from the arrival equation). The
marginal likelihood is then log N(y; H mean, H P H' + R), the posterior by the Kalman
update in moment form: nothing of the module's rows, whitening, banded solver or
Schur complements is used.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pandas as pd
import pytest
from scipy.stats import chi2

from rafostrack.calibrate import kalman
from rafostrack.calibrate.timing_problem import hinging_sources, timing_problem, without_sources
from rafostrack.config import load_config
from rafostrack.model.geodesy import displace, local_offsets_km, range_m
from rafostrack.sim.scenarios import synthetic_scenario
from rafostrack.sim.simulate import simulate_mission
from rafostrack.summaries.estimates import Estimate

NODE = 6  # east, north, v_east, v_north, clock, clock rate
T0 = np.datetime64("2010-01-01T00:00", "ns")
LAT0, LON0 = -58.0, -90.0


def _small_problem(seed: int, end_fix: bool, n_nodes: int = 9, n_heard: int = 3) -> tuple[kalman.Problem, np.ndarray]:
    """Nodes at uneven intervals (0.5-3 days) along a drifting nominal track, 3 beacons
    300-700 km away, ~85% of (node, beacon) pairs heard; TOAs with a sound speed, offsets
    and noise that the catalogue delays do not know. Returns the problem and node days."""
    rng = np.random.default_rng(seed)
    days = np.concatenate([[0.0], np.cumsum(rng.choice([0.5, 1.0, 2.0, 3.0], n_nodes - 1))])
    time = T0 + (days * 86400e9).astype("timedelta64[ns]")
    lat, lon = displace(np.full(n_nodes, LAT0), np.full(n_nodes, LON0), 4 * days, -2 * days + rng.normal(0, 3, n_nodes))
    angle = rng.uniform(0, 2 * np.pi) + 2 * np.pi * np.arange(n_heard) / n_heard
    dist = rng.uniform(300, 700, n_heard)
    blat, blon = displace(np.full(n_heard, LAT0), np.full(n_heard, LON0), dist * np.cos(angle), dist * np.sin(angle))
    pairs = [(k, i) for k in range(1, n_nodes) for i in range(n_heard) if rng.random() < 0.85]
    node, beacon = (np.array(v) for v in zip(*pairs, strict=True))
    mid = np.array([days[node][beacon == i].mean() for i in range(n_heard)])
    delay = rng.uniform(0, 1500, n_heard)[beacon]
    toa = delay + range_m(lat[node], lon[node], blat[beacon], blon[beacon]) / 1484.0
    toa += rng.normal(0, 1.5, len(node)) + rng.normal(0, 2, n_heard)[beacon]
    problem = kalman.Problem(
        time=time,
        lat=np.asarray(lat),
        lon=np.asarray(lon),
        launch_sd_km=1.0,
        end_sd_km=2.0 if end_fix else None,
        node=node,
        beacon=beacon,
        toa_s=toa,
        delay_s=delay,
        drift_days=days[node] - mid[beacon],
        beacon_lat=np.asarray(blat),
        beacon_lon=np.asarray(blon),
        slowness_s_per_m=1 / 1480.0,
    )
    return problem, days


def _statics(problem: kalman.Problem) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:
    """Indices of (ds, offsets a_i, drifts d_i, slownesses ds_i), laid out as the module
    documents: nodes, then vbar (2), ds, a (H), d (H), ds_i (H)."""
    base, h = NODE * problem.n_nodes, problem.n_heard
    return base + 2, base + 3 + np.arange(h), base + 3 + h + np.arange(h), base + 3 + 2 * h + np.arange(h)


def _predicted(problem: kalman.Problem, x: np.ndarray) -> np.ndarray:
    """The arrival equation: D + a_i + d_i (days - mid) + c_k + R(p_k, b_i) (s0 + ds + ds_i)."""
    k, i = problem.node, problem.beacon
    ds, a, d, dsi = _statics(problem)
    lat, lon = displace(problem.lat[k], problem.lon[k], x[NODE * k], x[NODE * k + 1])
    r = range_m(lat, lon, problem.beacon_lat[i], problem.beacon_lon[i])
    slow = problem.slowness_s_per_m + x[ds] + x[dsi][i]
    return problem.delay_s + x[a][i] + x[d][i] * problem.drift_days + x[NODE * k + 4] + r * slow


def _jacobian(problem: kalman.Problem, x: np.ndarray) -> np.ndarray:
    k, i = problem.node, problem.beacon
    rows = np.arange(len(k))
    jac = np.zeros((len(k), problem.n_unknowns))
    h = 1e-3  # km; each arrival depends on its own node only, so all nodes move at once
    for axis in range(2):
        plus, minus = x.copy(), x.copy()
        plus[NODE * np.arange(problem.n_nodes) + axis] += h
        minus[NODE * np.arange(problem.n_nodes) + axis] -= h
        jac[rows, NODE * k + axis] = (_predicted(problem, plus) - _predicted(problem, minus)) / (2 * h)
    lat, lon = displace(problem.lat[k], problem.lon[k], x[NODE * k], x[NODE * k + 1])
    r = range_m(lat, lon, problem.beacon_lat[i], problem.beacon_lon[i])
    ds, a, d, dsi = _statics(problem)
    jac[rows, NODE * k + 4] = 1.0
    jac[rows, ds] = r
    jac[rows, a[i]] = 1.0
    jac[rows, d[i]] = problem.drift_days
    jac[rows, dsi[i]] = r
    return jac


def _ou_moments(dt: float, sd: float, t: float) -> tuple[float, float, float, float]:
    """(a, Var e_x, Cov(e_x, e_v), Var e_v) of the integrated OU over dt (closed forms)."""
    a = math.exp(-dt / t)
    return a, sd**2 * t**2 * (2 * dt / t - 3 + 4 * a - a * a), sd**2 * t * (1 - a) ** 2, sd**2 * (1 - a * a)


def _prior(problem: kalman.Problem, days: np.ndarray, hyper: kalman.Hyper, priors: kalman.KalmanPriors):
    """Prior mean c and factor M (unknowns = c + M z) from the forward recursions."""
    n, k_nodes, h = problem.n_unknowns, problem.n_nodes, problem.n_heard
    base = NODE * k_nodes
    m, c = np.zeros((n, n)), np.zeros(n)
    fresh = iter(range(n))

    def draw(index: int, sd: float) -> None:
        m[index, next(fresh)] += sd

    s0 = problem.slowness_s_per_m
    ds, a_idx, d_idx, dsi_idx = _statics(problem)
    for axis in range(2):
        draw(base + axis, priors.mean_current_km_per_day)
    draw(ds, priors.sound_speed_m_s * s0**2)
    for i in range(h):
        draw(a_idx[i], priors.offset_s)
        draw(d_idx[i], priors.drift_s_per_day)
        draw(dsi_idx[i], priors.beacon_sound_speed_m_s * s0**2)
    sd, t, q = hyper.velocity_sd_km_per_day, hyper.decorrelation_days, hyper.clock_rate_sd_s_per_day
    for axis in range(2):  # launch position about the fix; velocity about the mean current
        draw(axis, problem.launch_sd_km)
        m[2 + axis] = m[base + axis]
        draw(2 + axis, sd)
    draw(4, problem.clock_sd_s[0])
    draw(5, priors.clock_rate_s_per_day)
    east, north = local_offsets_km(problem.lat[1:], problem.lon[1:], problem.lat[:-1], problem.lon[:-1])
    for k in range(k_nodes - 1):
        dt = days[k + 1] - days[k]
        p0, p1 = NODE * k, NODE * (k + 1)
        a, var_x, cov_xv, var_v = _ou_moments(dt, sd, t)
        for axis, nominal in enumerate((east[k], north[k])):
            chol = np.linalg.cholesky([[var_x, cov_xv], [cov_xv, var_v]])
            z1, z2 = next(fresh), next(fresh)
            # offsets from the nominal track: x1 - x0 = (true displacement) - nominal displacement
            for out in (m, c):
                out[p1 + axis] = (
                    out[p0 + axis] + t * (1 - a) * out[p0 + 2 + axis] + (dt - t * (1 - a)) * out[base + axis]
                )
                out[p1 + 2 + axis] = a * out[p0 + 2 + axis] + (1 - a) * out[base + axis]
            c[p1 + axis] -= nominal
            m[p1 + axis, z1] += chol[0, 0]
            m[p1 + 2 + axis, [z1, z2]] += chol[1]
        chol = np.linalg.cholesky(q * q * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]]))
        z1, z2 = next(fresh), next(fresh)
        m[p1 + 4] = m[p0 + 4] + dt * m[p0 + 5]
        m[p1 + 5] = m[p0 + 5]
        m[p1 + 4, z1] += chol[0, 0]
        m[p1 + 5, [z1, z2]] += chol[1]
    assert next(fresh, None) is None  # one fresh draw per unknown: the prior is proper
    return c, m


def _dense(problem, days, u, weight, hyper, priors):
    """(log p(y), posterior mean, posterior covariance) of the model linearised at u."""
    c, m = _prior(problem, days, hyper, priors)
    jac = _jacobian(problem, u)
    obs, y, var = [jac], [problem.toa_s - _predicted(problem, u) + jac @ u], [hyper.toa_sigma_s**2 / weight]
    if problem.end_sd_km is not None:  # the end fix: position and clock residual observed as 0
        last = NODE * (problem.n_nodes - 1)
        select = np.zeros((3, problem.n_unknowns))
        select[[0, 1, 2], [last, last + 1, last + 4]] = 1.0
        obs.append(select)
        y.append(np.zeros(3))
        var.append(np.array([problem.end_sd_km**2, problem.end_sd_km**2, problem.clock_sd_s[1] ** 2]))
    h, y, r = np.vstack(obs), np.concatenate(y), np.concatenate(var)
    p = m @ m.T
    s = h @ p @ h.T + np.diag(r)
    innovation = y - h @ c
    log_ml = -0.5 * (innovation @ np.linalg.solve(s, innovation) + np.linalg.slogdet(s)[1] + len(y) * np.log(2 * np.pi))
    gain = np.linalg.solve(s, h @ p).T
    return log_ml, c + gain @ innovation, p - gain @ h @ p


HYPER = kalman.Hyper(velocity_sd_km_per_day=4.0, decorrelation_days=3.0, toa_sigma_s=1.7, clock_rate_sd_s_per_day=0.02)


def _linearisation_point(problem: kalman.Problem, kind: str, rng: np.random.Generator) -> np.ndarray:
    """u = 0, or nonzero clocks and static parameters. (Positions stay at the nominal track:
    the module takes its range gradient in the displaced point's tangent plane, an
    approximation of the exact Jacobian of order offset / Earth radius.)"""
    u = np.zeros(problem.n_unknowns)
    if kind == "shifted":
        ds, a, d, dsi = _statics(problem)
        u[NODE * np.arange(problem.n_nodes) + 4] = rng.normal(0, 0.5, problem.n_nodes)
        u[NODE * np.arange(problem.n_nodes) + 2] = rng.normal(0, 3, problem.n_nodes)
        u[ds] = 5 * problem.slowness_s_per_m**2
        u[a], u[d], u[dsi] = rng.normal(0, 2, len(a)), rng.normal(0, 0.01, len(d)), rng.normal(0, 1e-6, len(dsi))
    return u


@pytest.mark.parametrize("point", ["zero", "shifted"])
@pytest.mark.parametrize("end_fix", [True, False], ids=["end-fix", "no-end-fix"])
@pytest.mark.parametrize("weights", ["ones", "mixed"])
def test_evidence_and_posterior_mean_match_the_dense_gaussian(point, end_fix, weights):
    problem, days = _small_problem(seed=1 if end_fix else 2, end_fix=end_fix)
    rng = np.random.default_rng(3)
    weight = np.ones(len(problem.toa_s)) if weights == "ones" else rng.uniform(0.05, 1.0, len(problem.toa_s))
    u = _linearisation_point(problem, point, rng)
    priors = kalman.KalmanPriors()
    lin = kalman.linearise(problem, u, weight, priors)
    step, log_ml = kalman.solve_step(lin, HYPER)
    want_ml, want_mean, _ = _dense(problem, days, u, weight, HYPER, priors)
    assert log_ml == pytest.approx(want_ml, abs=1e-5)
    # The Gauss-Newton step of a model that is linear at u lands on the posterior mean.
    scale = np.sqrt(np.diag(_dense(problem, days, u, weight, HYPER, priors)[2]))
    np.testing.assert_allclose((u + step - want_mean) / scale, 0.0, atol=1e-6)
    # Another hyperparameter value gives another evidence, by the same amount in both.
    other = dataclasses.replace(HYPER, toa_sigma_s=1.2, decorrelation_days=6.0)
    assert kalman.solve_step(lin, other)[1] - log_ml == pytest.approx(
        _dense(problem, days, u, weight, other, priors)[0] - want_ml, abs=1e-5
    )


@pytest.mark.parametrize("end_fix", [True, False], ids=["end-fix", "no-end-fix"])
def test_position_covariances_match_the_dense_posterior(end_fix):
    """Total: the 2x2 position blocks of the posterior covariance. Nuisance part: total
    minus the covariance of positions given the clock and timing unknowns, here the
    conditional covariance of (positions, velocities) given the rest, by the Schur
    complement of the dense posterior covariance."""
    problem, days = _small_problem(seed=4, end_fix=end_fix, n_nodes=10, n_heard=4)
    weight = np.random.default_rng(5).uniform(0.3, 1.0, len(problem.toa_s))
    u = np.zeros(problem.n_unknowns)
    priors = kalman.KalmanPriors()
    total, nuisance = kalman.position_covariances(kalman.linearise(problem, u, weight, priors), HYPER)
    _, _, post = _dense(problem, days, u, weight, HYPER, priors)
    k = np.arange(problem.n_nodes)
    want_total = np.stack([post[NODE * j : NODE * j + 2, NODE * j : NODE * j + 2] for j in k])
    np.testing.assert_allclose(total, want_total, rtol=1e-6, atol=1e-8)
    motion = (NODE * k[:, None] + np.arange(4)).ravel()
    rest = np.setdiff1d(np.arange(problem.n_unknowns), motion)
    given = post[np.ix_(motion, motion)] - post[np.ix_(motion, rest)] @ np.linalg.solve(
        post[np.ix_(rest, rest)], post[np.ix_(rest, motion)]
    )
    want_nuisance = want_total - np.stack([given[4 * j : 4 * j + 2, 4 * j : 4 * j + 2] for j in k])
    np.testing.assert_allclose(nuisance, want_nuisance, rtol=1e-5, atol=1e-7)
    assert np.all(np.linalg.eigvalsh(nuisance) >= 0) and np.trace(nuisance, axis1=1, axis2=2).max() > 0.01


@pytest.mark.parametrize("end_fix", [True, False], ids=["end-fix", "no-end-fix"])
@pytest.mark.parametrize("hyper", [HYPER, kalman.Hyper(12.0, 0.8, 3.5, 0.08)], ids=["moderate", "far"])
def test_evidence_gradient_matches_differences_of_the_dense_evidence(end_fix, hyper):
    """evidence_and_gradient: its value is solve_step's, and its gradient in log h is the
    oracle's log evidence differenced centrally (step 1e-4 in log h, error ~1e-8 relative)."""
    problem, days = _small_problem(seed=7 if end_fix else 8, end_fix=end_fix, n_nodes=11, n_heard=4)
    rng = np.random.default_rng(9)
    weight = rng.uniform(0.05, 1.0, len(problem.toa_s))
    u = _linearisation_point(problem, "shifted", rng)
    priors = kalman.KalmanPriors()
    lin = kalman.linearise(problem, u, weight, priors)
    log_ml, grad = kalman.evidence_and_gradient(lin, hyper)
    assert log_ml == kalman.solve_step(lin, hyper)[1]
    step = 1e-4
    want = np.zeros(4)
    for j in range(4):
        up, down = hyper.vector(), hyper.vector()
        up[j] += step
        down[j] -= step
        want[j] = (
            _dense(problem, days, u, weight, kalman.Hyper(*np.exp(up)), priors)[0]
            - _dense(problem, days, u, weight, kalman.Hyper(*np.exp(down)), priors)[0]
        ) / (2 * step)
    np.testing.assert_allclose(grad, want, rtol=1e-5, atol=1e-5)
    assert np.abs(want).min() > 1e-3  # every component is tested, none is ~0


def _with_far_singleton(problem: kalman.Problem, toa_error_s: float) -> kalman.Problem:
    """The problem with one more source, 1800 km from the mid-record node and heard there
    once, at its true arrival time (the truth's 1484 m/s, no offset) + toa_error_s."""
    k = problem.n_nodes // 2
    blat, blon = displace(np.array([problem.lat[k]]), np.array([problem.lon[k]]), np.array([1800.0]), np.array([300.0]))
    toa = range_m(problem.lat[k], problem.lon[k], blat[0], blon[0]) / 1484.0 + toa_error_s
    return dataclasses.replace(
        problem,
        node=np.r_[problem.node, k],
        beacon=np.r_[problem.beacon, problem.n_heard],
        toa_s=np.r_[problem.toa_s, toa],
        delay_s=np.r_[problem.delay_s, 0.0],
        drift_days=np.r_[problem.drift_days, 0.0],
        beacon_lat=np.r_[problem.beacon_lat, blat],
        beacon_lon=np.r_[problem.beacon_lon, blon],
    )


def test_sound_speed_influence_matches_a_solve_without_each_source():
    """Per source, the speed fitted without its arrivals (the oracle: the problem rebuilt
    without them, linearised at the same point, one solve) minus the fitted speed; the
    speed's sd from the dense posterior covariance."""
    problem, days = _small_problem(seed=10, end_fix=True, n_nodes=14, n_heard=4)
    problem = _with_far_singleton(problem, toa_error_s=6.0)
    mid = np.zeros(problem.n_heard)
    priors = kalman.KalmanPriors()
    fit = kalman.fit(problem, HYPER, _no_multipath, mid)
    shift, sd = kalman.sound_speed_influence(problem, fit, priors)
    lin = kalman.linearise(problem, fit.unknowns, fit.weight, priors)
    ds = fit.unknowns[problem.ds] + kalman.solve_step(lin, fit.hyper)[0][problem.ds]
    speed = 1.0 / (problem.slowness_s_per_m + ds)
    for h in range(problem.n_heard):
        keep = problem.beacon != h
        others = np.flatnonzero(np.arange(problem.n_heard) != h)
        sub = dataclasses.replace(
            problem,
            node=problem.node[keep],
            beacon=np.searchsorted(others, problem.beacon[keep]),
            toa_s=problem.toa_s[keep],
            delay_s=problem.delay_s[keep],
            drift_days=problem.drift_days[keep],
            beacon_lat=problem.beacon_lat[others],
            beacon_lon=problem.beacon_lon[others],
        )
        columns = np.r_[np.arange(sub.ds + 1), *(problem.per_beacon(block)[others] for block in range(3))]
        u = fit.unknowns[columns]
        step = kalman.solve_step(kalman.linearise(sub, u, fit.weight[keep], priors), fit.hyper)[0]
        without = 1.0 / (sub.slowness_s_per_m + u[sub.ds] + step[sub.ds])
        assert shift[h] == pytest.approx(without - speed, abs=1e-6)
    assert abs(shift[-1]) > 1.0  # the far singleton moves the speed
    _, _, post = _dense(problem, days, fit.unknowns, fit.weight, fit.hyper, priors)
    assert sd == pytest.approx(np.sqrt(post[problem.ds, problem.ds]) * speed**2, rel=1e-4)


@pytest.mark.parametrize("seed", [1, 3])
def test_a_far_source_heard_once_off_its_time_is_left_out_of_the_calibration(seed):
    """calibrate.hinging_sources: one arrival of a far source, 10 s off its true time (as
    clutter near its predicted time would be), pulls the shared speed by more than its sd
    and is left out; the speed refitted without it is within 1 m/s of the fit with that
    arrival on time. On time, nothing is left out."""
    base, _ = _small_problem(seed=seed, end_fix=True, n_nodes=40, n_heard=4)
    priors = kalman.KalmanPriors()
    fits = {}
    for error in (0.0, 10.0):
        problem = _with_far_singleton(base, error)
        mid = np.zeros(problem.n_heard)
        fit = kalman.fit(problem, HYPER, _no_multipath, mid)
        hinging = hinging_sources(problem, fit, priors)
        assert hinging.tolist() == [False] * base.n_heard + [error != 0.0]
        if hinging.any():
            problem, mid = without_sources(problem, mid, hinging)
            fit = kalman.fit(problem, fit.hyper, _no_multipath, mid)
        fits[error] = fit.sound_speed_m_s
    assert fits[10.0] == pytest.approx(fits[0.0], abs=1.0)


def test_fit_hyper_maximises_dense_evidence_plus_hyperprior():
    """No step of 10% along any hyperparameter raises the oracle's log evidence + the weak
    log-normal hyperprior (written here) above the value at fit_hyper's answer by more than
    the search's stopping rule allows: a gradient under 0.1 nats per unit of log
    hyperparameter, so a 10% step (0.095 in log) gains at most ~0.01 nats."""
    problem, days = _small_problem(seed=6, end_fix=True, n_nodes=12, n_heard=4)
    u = np.zeros(problem.n_unknowns)
    weight = np.ones(len(problem.toa_s))
    priors = kalman.KalmanPriors()
    best = kalman.fit_hyper(kalman.linearise(problem, u, weight, priors), kalman.Hyper(8.0, 3.0, 4.0, 0.01))

    def objective(h: kalman.Hyper) -> float:
        z = (np.log(dataclasses.astuple(h)) - np.log([5.0, 5.0, 2.0, 0.01])) / np.array([1.5, 1.5, 1.0, 1.0])
        return _dense(problem, days, u, weight, h, priors)[0] - 0.5 * float(z @ z)

    at_best = objective(best)
    values = np.array(dataclasses.astuple(best))
    for j in range(4):
        for factor in (0.9, 1.1):
            moved = values.copy()
            moved[j] *= factor
            lower, upper = kalman.Hyper.LOWER[j], kalman.Hyper.UPPER[j]
            if lower <= moved[j] <= upper:
                assert objective(kalman.Hyper(*moved)) <= at_best + 0.01, (j, factor)
    assert abs(best.toa_sigma_s - 1.5) < 0.8  # the simulated noise sd is 1.5 s (+ offsets taken up by a_i)


def test_fit_hyper_holds_the_clock_rate_sd_at_its_floor():
    """A floor on q above the free optimum's holds q at the floor (the evidence falls away
    from the optimum) and refits the others; a floor below it changes nothing."""
    problem, _ = _small_problem(seed=6, end_fix=True, n_nodes=12, n_heard=4)
    lin = kalman.linearise(problem, np.zeros(problem.n_unknowns), np.ones(len(problem.toa_s)), kalman.KalmanPriors())
    start = kalman.Hyper(8.0, 3.0, 4.0, 0.01)
    free = kalman.fit_hyper(lin, start)
    q = free.clock_rate_sd_s_per_day
    assert kalman.Hyper.LOWER[3] < q < kalman.Hyper.UPPER[3] / 10
    held = kalman.fit_hyper(lin, start, kalman.Hyper.lower_with_clock_floor(5 * q))
    assert held.clock_rate_sd_s_per_day == pytest.approx(5 * q)
    assert kalman.evidence_and_gradient(lin, held)[0] < kalman.evidence_and_gradient(lin, free)[0]
    below = kalman.fit_hyper(lin, start, kalman.Hyper.lower_with_clock_floor(q / 5))
    assert dataclasses.astuple(below) == pytest.approx(dataclasses.astuple(free), rel=1e-6)


# ---------------------------------------------------------------------------------------
# A simulated float with known timing nuisances.

C_TRUE = 1488.5  # the truth's sound speed: 0.57% above the configured 1480 m/s
SIGMA_TRUE = 0.8
DAYS = 90
ONE_DAY = np.timedelta64(86400, "s").astype("timedelta64[ns]")


def _crossing_float(seed: int):
    """A 90-day float that crosses the synthetic ring of 8 beacons (launch 150 km inside
    from one beacon, end fix 150 km inside from the opposite one), simulated with a sound
    speed, per-beacon offsets (1.5-3 s either way) and source drift errors (up to 0.01
    s/day) that the catalogue lacks, and a float clock wandering by up to 1.5 s between its
    measured ends. Returns the calibrator's problem (true labels as confident labels, a
    nominal track 3 km off the truth) and the truth."""
    config = load_config()
    beacons, (info,) = synthetic_scenario(days=DAYS, rng=seed)
    east, west = int(np.argmax(beacons.lon)), int(np.argmin(beacons.lon))
    de, dn = local_offsets_km(beacons.lat[west], beacons.lon[west], beacons.lat[east], beacons.lon[east])
    dist = math.hypot(float(de), float(dn))
    launch = displace(beacons.lat[east], beacons.lon[east], 150 * de / dist, 150 * dn / dist)
    end = displace(beacons.lat[west], beacons.lon[west], -150 * de / dist, -150 * dn / dist)
    info = dataclasses.replace(
        info, launch_lat=float(launch[0]), launch_lon=float(launch[1]), end_lat=float(end[0]), end_lon=float(end[1])
    )
    info = dataclasses.replace(info, max_signals=8)
    rng = np.random.default_rng(100 + seed)
    n = len(beacons)
    offset_error = rng.choice([-1.0, 1.0], n) * rng.uniform(1.5, 3.0, n)
    drift_error = rng.uniform(-0.01, 0.01, n)
    knots = info.launch_time + np.arange(DAYS + 1) * ONE_DAY
    frac = np.arange(DAYS + 1) / DAYS
    wander = 1.5 * np.sin(2 * np.pi * 1.3 * frac + 0.4) * 4 * frac * (1 - frac)  # 0 at both ends
    true_beacons = dataclasses.replace(beacons, offset_s=beacons.offset_s + offset_error, drift_s_per_day=drift_error)
    model = dataclasses.replace(
        config.model, sound_speed_m_s=C_TRUE, toa_sigma_s=SIGMA_TRUE, multipath_fraction=0.0, echo_fraction=0.0
    )
    model = dataclasses.replace(model, clutter_rate=0.1)
    true_info = dataclasses.replace(info, clock_residual=(knots, wander))
    sim = simulate_mission(true_beacons, [true_info], model, rng, eddy_timescale_days=5.0).floats[0]
    labels = pd.DataFrame(
        [(w.time, t, b, 1.0) for w in sim.record.windows for t, b in zip(w.toa_s, w.beacon_id, strict=True) if b],
        columns=["time", "toa_s", "beacon_id", "prob"],
    )
    times = np.array([w.time for w in sim.record.windows], dtype="datetime64[ns]")
    at = sim.truth.set_index("time").loc[times]
    lat, lon = displace(at["lat"], at["lon"], rng.normal(0, 3, len(times)), rng.normal(0, 3, len(times)))
    track = pd.DataFrame({"time": times, "lat": lat, "lon": lon, "ambiguous": False})
    problem, heard, mid = timing_problem(Estimate("smoothed", track, labels, pd.DataFrame()), beacons, info, config)
    truth = {
        "offset_s": offset_error[heard],
        "drift_s_per_day": drift_error[heard],
        "clock_s": np.interp(problem.time.astype(np.int64).astype(float), knots.astype(np.int64).astype(float), wander),
        "track": sim.truth.set_index("time").loc[problem.time],
    }
    start = kalman.Hyper(config.motion.velocity_sd_km_per_day, config.motion.decorrelation_days, 2.0, 0.01)
    return problem, mid, start, truth


def _no_multipath(residual_s: np.ndarray, toa_sigma_s: float) -> np.ndarray:
    return np.ones_like(residual_s)


def _errors_km(fit: kalman.KalmanFit, track: pd.DataFrame) -> np.ndarray:
    east, north = local_offsets_km(fit.lat, fit.lon, track["lat"].to_numpy(), track["lon"].to_numpy())
    return np.column_stack([east, north])


@pytest.mark.parametrize("seed", [0, 2])
def test_a_simulated_float_recovers_its_timing_nuisances(seed):
    """The fitted corrections against the simulation's truth, with the covariance the
    module's own normal matrix gives (N^-1 at the solution): the reported per-beacon
    (sound speed as slowness, offset correction, drift correction) are within the 99.9%
    chi-square bound of the truth, and that bound rejects the catalogue by far; the
    clock wander, the TOA noise sd and the sound speed are recovered; the positions are
    much better than the same smoother's with the timing corrections frozen at the
    catalogue; and the reported position covariance covers the truth at about its rate."""
    problem, mid, start, truth = _crossing_float(seed)
    fit = kalman.fit(problem, start, _no_multipath, mid)
    lin = kalman.linearise(problem, fit.unknowns, fit.weight, kalman.KalmanPriors())
    cov = np.linalg.inv(lin.normal(fit.hyper).jtj.toarray())
    h, s0 = problem.n_heard, problem.slowness_s_per_m
    ds, a, d, dsi = _statics(problem)
    # The reported corrections as linear maps of the unknowns.
    g = np.zeros((3 * h, problem.n_unknowns))
    g[np.arange(h), ds] = 1.0
    g[np.arange(h), dsi] = 1.0  # total slowness deviation of beacon i
    g[h + np.arange(h), a] = 1.0
    g[h + np.arange(h), d] = -mid  # offset correction a_i - d_i mid_i
    g[2 * h + np.arange(h), d] = 1.0
    reported = np.concatenate([1 / fit.beacon_sound_speed_m_s - s0, fit.offset_s, fit.drift_s_per_day])
    np.testing.assert_allclose(g @ fit.unknowns, reported, rtol=1e-9, atol=1e-12)
    true = np.concatenate([np.full(h, 1 / C_TRUE - s0), truth["offset_s"], truth["drift_s_per_day"]])
    cov_g = g @ cov @ g.T
    bound = chi2.ppf(0.999, 3 * h)
    error = reported - true
    assert error @ np.linalg.solve(cov_g, error) < bound
    assert true @ np.linalg.solve(cov_g, true) > 10 * bound  # the catalogue (no correction) is excluded
    off_err = fit.offset_s - truth["offset_s"]
    assert np.sqrt(np.mean(off_err**2)) < 0.4 * np.sqrt(np.mean(truth["offset_s"] ** 2))
    se_c = np.sqrt(cov[ds, ds]) * fit.sound_speed_m_s**2
    assert abs(fit.sound_speed_m_s - C_TRUE) < min(3 * se_c, 0.5 * (C_TRUE - 1480.0))
    assert abs(fit.hyper.toa_sigma_s / SIGMA_TRUE - 1) < 0.15
    clock_rms = np.sqrt(np.mean(truth["clock_s"] ** 2))
    assert np.sqrt(np.mean((fit.clock_s - truth["clock_s"]) ** 2)) < 0.35 * clock_rms
    # Positions: calibrated against uncalibrated (the statics' priors shrunk to nothing).
    frozen = kalman.KalmanPriors(sound_speed_m_s=1e-6, beacon_sound_speed_m_s=1e-6, offset_s=1e-6, drift_s_per_day=1e-8)
    uncalibrated = kalman.fit(problem, start, _no_multipath, mid, priors=frozen)
    err = _errors_km(fit, truth["track"])
    rmse = np.sqrt(np.mean(np.sum(err**2, axis=1)))
    rmse_uncalibrated = np.sqrt(np.mean(np.sum(_errors_km(uncalibrated, truth["track"]) ** 2, axis=1)))
    assert rmse < 0.6 * rmse_uncalibrated
    d2 = np.einsum("ki,kij,kj->k", err, np.linalg.inv(fit.position_cov_km2), err)
    assert np.mean(d2 < chi2.ppf(0.95, 2)) >= 0.8
    assert 0.2 <= np.mean(d2 < chi2.ppf(0.5, 2)) <= 0.9


def test_leaving_sources_out_keeps_each_sources_released_prior():
    """`without_sources` drops the left-out sources' entries of `released` with them."""
    problem, _ = _small_problem(seed=6, end_fix=True, n_nodes=12, n_heard=4)
    problem = dataclasses.replace(problem, released=np.array([False, True, False, True]))
    kept, _ = without_sources(problem, np.zeros(4), np.array([True, False, False, False]))
    assert kept.released.tolist() == [True, False, True]
    kalman.linearise(kept, np.zeros(kept.n_unknowns), np.ones(len(kept.toa_s)), kalman.KalmanPriors())
