"""The ABC engine for floats (rafostrack.engines.abc): its matching distance against brute
force, its window simulator against the model, its likelihood and label marginals against
the exact ones (the exact engine, which tests/test_engines.py holds to the brute-force
oracle at 1e-9), its seeding, and its place behind `RankedArrivals`."""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest
from numpy.typing import NDArray

from rafostrack.config import load_config, with_overrides
from rafostrack.domain import Particles, Window
from rafostrack.engines import ENGINES, SimulatingEngine, WindowPrediction, engine_from_config, exact
from rafostrack.engines.abc import ABCEngine, align, simulate_windows
from rafostrack.likelihoods import RankedArrivals, arrivals_from_config
from rafostrack.model.measurement import association_factors
from rafostrack.problem import FloatProblem
from rafostrack.run.one_pass import Tracker

WINDOW_S = 4200.0


def brute_force_distance(obs: NDArray, sim: NDArray, gap: float) -> float:
    """min over every partial matching (crossings allowed) of pair costs plus gaps."""
    sim = sim[np.isfinite(sim)]
    best = np.inf
    for used in range(min(len(obs), len(sim)) + 1):
        for rows in itertools.combinations(range(len(obs)), used):
            for cols in itertools.permutations(range(len(sim)), used):
                pairs = sum((obs[a] - sim[b]) ** 2 for a, b in zip(rows, cols, strict=True))
                unmatched = len(obs) + len(sim) - 2 * used
                best = min(best, pairs + (unmatched * gap if unmatched else 0.0))
    return best


@pytest.mark.parametrize("gap", [0.5 * 10.0**2, 8.0, np.inf])
def test_matching_distance_is_the_best_partial_matching(gap):
    rng = np.random.default_rng(0)
    for _ in range(40):
        k, r = int(rng.integers(0, 5)), int(rng.integers(1, 5))
        obs = np.sort(rng.uniform(0, 60, k))
        sims = np.sort(np.where(rng.random((6, r)) < 0.8, rng.uniform(0, 60, (6, r)), np.inf), axis=1)
        rho, match = align(obs, sims, gap)
        assert match is not None
        for n in range(6):
            assert rho[n] == pytest.approx(brute_force_distance(obs, sims[n], gap), rel=1e-12)
            if np.isfinite(rho[n]):  # the traceback's matching has that cost
                paired = match[n] >= 0
                cost = ((obs[paired] - sims[n, match[n, paired]]) ** 2).sum()
                n_unmatched = k + int(np.isfinite(sims[n]).sum()) - 2 * int(paired.sum())
                assert cost + (n_unmatched * gap if n_unmatched else 0.0) == pytest.approx(rho[n], rel=1e-12)
                assert np.all(np.diff(match[n, paired]) > 0)  # no crossings


def test_simulated_windows_follow_the_model():
    model = dataclasses.replace(load_config().model, clutter_rate=1.5, multipath_fraction=0.0, echo_fraction=0.0)
    mu = np.array([[500.0, 1200.0, 4300.0, 2000.0]])  # the third arrives after the window
    p_detect = np.array([[0.9, 0.6, 0.9, 0.3]])
    rng = np.random.default_rng(1)
    n = 40_000
    toa, label = simulate_windows(mu, p_detect, n, model=model, window_s=WINDOW_S, max_signals=None, rng=rng)
    both = np.isfinite(toa[..., 1:])
    assert np.all(toa[..., 1:][both] >= toa[..., :-1][both])
    for i in (0, 1, 3):
        heard = label[0] == i
        assert heard.sum(axis=1).max() == 1
        assert heard.any(axis=1).mean() == pytest.approx(p_detect[0, i], abs=0.01)
        resid = toa[0][heard] - mu[0, i]
        assert resid.std() == pytest.approx(model.toa_sigma_s, rel=0.03) and abs(resid.mean()) < 0.05
    assert not (label == 2).any()
    assert (label == 4).sum(axis=-1).mean() == pytest.approx(1.5, rel=0.03)  # clutter
    stored, stored_label = simulate_windows(mu, p_detect, n, model=model, window_s=WINDOW_S, max_signals=2, rng=rng)
    assert stored.shape[-1] == 2
    first = np.where(stored_label[0, :, 0] == 0)[0]  # beacon 0 (mu 500 s) is first unless clutter beat it
    assert len(first) / n == pytest.approx(0.9 * np.exp(-1.5 * 500.0 / WINDOW_S), abs=0.01)


def test_simulated_echoes_follow_the_model():
    """With echoes a detected signal comes twice with probability e, Exp(tau) apart, both
    labelled with the source."""
    model = dataclasses.replace(
        load_config().model, clutter_rate=0.5, multipath_fraction=0.0, echo_fraction=0.2, multipath_delay_s=15.0
    )
    mu, p_detect = np.array([[500.0, 2000.0]]), np.array([[0.8, 0.8]])
    toa, label = simulate_windows(
        mu, p_detect, 40_000, model=model, window_s=WINDOW_S, max_signals=None, rng=np.random.default_rng(3)
    )
    heard = (label[0] == 0).sum(axis=1)
    assert heard.max() == 2 and np.mean(heard == 2) == pytest.approx(0.8 * 0.2, abs=0.01)
    pairs = np.sort(np.where(label[0] == 0, toa[0], np.inf), axis=1)[heard == 2]
    assert np.mean(pairs[:, 1] - pairs[:, 0]) == pytest.approx(15.0, rel=0.05)


def exact_loglik(mu: NDArray, p_detect: NDArray, toa: NDArray, r: int, model) -> tuple[NDArray, NDArray]:
    f = association_factors(mu, p_detect, toa, max_signals=r, window_s=WINDOW_S, model=model)
    result = exact.associate(f.log_match, f.log_unheard, log_echo=f.log_echo)
    return f.log_base + result.log_z, result.p_match


MU = np.array([[1000.0, 1500.0, 3000.0], [1003.0, 1496.0, 2990.0], [999.0, 1502.0, 1510.0]])
TOA = np.array([1001.0, 1498.5])


MODEL = dataclasses.replace(load_config().model, clutter_rate=0.3, multipath_fraction=0.1)
P_DETECT = np.full(MU.shape, 0.8)


def abc_loglik(eps: float, max_signals: int, simulations: int = 100_000) -> NDArray:
    engine = ABCEngine(tolerance_s=eps, simulations=simulations, gap_s=0.0)
    window = WindowPrediction(TOA, MU, P_DETECT, max_signals, WINDOW_S, MODEL, (5, 6, 7))
    return engine.simulate(window, marginals=False).log_z


@pytest.mark.parametrize("max_signals", [2, 4])
def test_abc_likelihood_is_the_exact_one_with_the_noise_widened_by_the_tolerance(max_signals):
    """Without gaps the kernel adds N(0, eps^2) to every stored TOA: the ABC likelihood
    estimates the exact one with sigma^2 + eps^2 (Gaussian and EMG alike), up to the
    ranking's blur, which is negligible here. Monte Carlo sd ~0.02."""
    eps = 2.0
    wide = dataclasses.replace(MODEL, toa_sigma_s=float(np.hypot(MODEL.toa_sigma_s, eps)))
    ours = abc_loglik(eps, max_signals)
    np.testing.assert_allclose(ours, exact_loglik(MU, P_DETECT, TOA, max_signals, wide)[0], atol=0.07)
    assert np.abs(ours - exact_loglik(MU, P_DETECT, TOA, max_signals, MODEL)[0]).max() > 0.3


def test_abc_likelihood_tends_to_the_exact_one_as_the_tolerance_shrinks():
    exact_ll, _ = exact_loglik(MU, P_DETECT, TOA, 2, MODEL)
    close, far = np.abs(abc_loglik(0.3, 2) - exact_ll), np.abs(abc_loglik(4.0, 2) - exact_ll)
    assert np.all(close < 0.12) and far.max() > 1.0, (close, far)


def test_abc_label_marginals_tend_to_the_exact_ones():
    """Two beacons predicted 3 s apart and one stored TOA between them: which one it came
    from is uncertain; the ABC marginals agree with the exact ones."""
    model = dataclasses.replace(load_config().model, clutter_rate=0.3, multipath_fraction=0.0)
    mu = np.array([[1000.0, 1003.0], [1000.0, 1006.0]])
    p_detect = np.full(mu.shape, 0.7)
    toa = np.array([1002.0])
    _, exact_p = exact_loglik(mu, p_detect, toa, 1, model)
    engine = ABCEngine(tolerance_s=0.3, simulations=60_000, gap_s=0.0)
    result = engine.simulate(WindowPrediction(toa, mu, p_detect, 1, WINDOW_S, model, (1, 2, 3)))
    assert 0.2 < exact_p[0, 0, 0] < 0.8
    np.testing.assert_allclose(result.p_match, exact_p, atol=0.04)
    assert np.all(result.p_match.sum(axis=1) <= 1 + 1e-12)


def test_gaps_keep_an_unexplainable_toa_from_zeroing_every_weight():
    """Three stored TOAs, but the model can make at most two signals (two beacons, almost
    no clutter, no echoes): without gaps every weight is zero; with gaps the particles are
    still ranked by the signals they do explain, and the stray TOA is called clutter."""
    model = dataclasses.replace(load_config().model, clutter_rate=1e-9, echo_fraction=0.0)
    mu = np.array([[1000.0, 1500.0], [1040.0, 1540.0]])  # the second particle is 40 s off
    toa = np.array([1000.5, 1499.0, 3333.0])
    window = WindowPrediction(toa, mu, np.full(mu.shape, 0.9), 4, WINDOW_S, model, (1, 1, 1))
    strict = ABCEngine(simulations=200, gap_s=0.0).simulate(window)
    assert np.all(np.isneginf(strict.log_z)) and np.all(strict.p_match == 0)
    robust = ABCEngine(simulations=200, gap_s=10.0).simulate(window)
    assert np.all(np.isfinite(robust.log_z)) and robust.log_z[0] > robust.log_z[1] + 10
    assert robust.p_match[0, 0, 0] > 0.8 and robust.p_match[0, 1, 1] > 0.8
    assert robust.p_match[:, :, 2].sum() == 0  # the stray TOA is called clutter


def test_engine_is_registered_configured_and_seeded():
    assert "abc" in ENGINES
    config = with_overrides(load_config(), filter={"engine": "abc"}, abc={"tolerance_s": 3.0, "simulations": 8})
    engine = engine_from_config(config)
    assert isinstance(engine, SimulatingEngine) and engine == ABCEngine(3.0, 8, 10.0, 0)
    model = config.model
    rng = np.random.default_rng(2)
    mu = rng.uniform(0, 4000, (20, 5))
    toa = np.sort(mu[0, :3] + 1.0)
    window = WindowPrediction(toa, mu, np.full(mu.shape, 0.9), 4, WINDOW_S, model, (0, 9, 9))
    a, b = engine.simulate(window), engine.simulate(window)
    np.testing.assert_array_equal(a.log_z, b.log_z)
    np.testing.assert_array_equal(a.p_match, b.p_match)
    other = dataclasses.replace(engine, stream=1).simulate(window)
    assert not np.array_equal(a.log_z, other.log_z)
    no_marginals = engine.simulate(window, marginals=False)
    np.testing.assert_array_equal(no_marginals.log_z, a.log_z)
    assert np.isnan(no_marginals.p_match).all()


def test_ranked_arrivals_pass_the_window_to_a_simulating_engine(sim_mission):
    sim = sim_mission.floats[0]
    config = with_overrides(load_config(), filter={"engine": "abc", "seed": 4})
    arrivals = arrivals_from_config(sim_mission.beacons, sim.info, config)
    assert isinstance(arrivals, RankedArrivals) and arrivals.seed == 4
    windows = [w for w in sim.record.windows if w.n_signals >= 3][:2]
    rng = np.random.default_rng(3)
    lat = sim.truth["lat"].iloc[5] + rng.normal(0, 0.05, 40)
    lon = sim.truth["lon"].iloc[5] + rng.normal(0, 0.05, 40)
    particles = Particles(lat, lon)
    first = arrivals.evaluate(particles, windows[0])
    assert first.loglik.shape == (40,) and np.isfinite(first.loglik).all()
    assert first.p_match is not None and first.p_match.shape == (40, len(first.beacon_index), windows[0].n_signals)
    again = arrivals.evaluate(particles, windows[0])
    np.testing.assert_array_equal(first.loglik, again.loglik)  # the window's draws are its own
    moved = Window(windows[1].time, windows[0].toa_s)  # same TOAs, another window time
    assert not np.array_equal(arrivals.evaluate(particles, moved).loglik, first.loglik)
    reseeded = arrivals_from_config(sim_mission.beacons, sim.info, with_overrides(config, filter={"seed": 5}))
    assert not np.array_equal(reseeded.evaluate(particles, windows[0]).loglik, first.loglik)


def test_a_float_tracked_with_abc_is_reproducible_bit_for_bit(sim_mission):
    sim = sim_mission.floats[0]
    record = type(sim.record)(sim.record.float_id, sim.record.path, sim.record.windows[:12])
    config = with_overrides(load_config(), filter={"engine": "abc", "particles": 150})

    def run(cfg):
        return Tracker.from_problem(FloatProblem(sim_mission.beacons, sim.info, cfg)).track(record)

    a, b = run(config), run(config)
    assert a.track.equals(b.track) and a.labels.equals(b.labels)
    c = run(with_overrides(config, abc={"stream": 1}))
    assert not a.track["lat"].equals(c.track["lat"])
