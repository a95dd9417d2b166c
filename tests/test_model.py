"""The measurement model against independent oracles.

The strongest check: p(T | X) is a probability density over everything a window can hold
(K = 0..r stored TOAs, ascending), so it must integrate to 1. That tests the horizon rule
(full vs partial windows), the late/missed factors and the clutter term together.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from geographiclib.geodesic import Geodesic
from scipy import integrate, stats

from rafostrack.config import load_config
from rafostrack.domain import BeaconTable, FloatInfo
from rafostrack.engines import exact
from rafostrack.model import measurement as m

NAT = np.datetime64("NaT", "ns")


def _model(**changes) -> m.ModelConfig:
    return dataclasses.replace(load_config().model, **changes)


def _loglik(mu, p_detect, toas, max_signals, window_s, model, ranked=True) -> float:
    f = m.association_factors(
        np.atleast_2d(mu),
        np.full((1, len(mu)), p_detect),
        np.asarray(toas, dtype=float),
        max_signals=max_signals,
        window_s=window_s,
        model=model,
        ranked=ranked,
    )
    return float(f.log_base + exact.associate(f.log_match, f.log_unheard, log_echo=f.log_echo).log_z[0])


@pytest.mark.parametrize(("multipath", "shape"), [(0.0, 1), (0.2, 1), (0.2, 2)])
def test_likelihood_integrates_to_one_r1(multipath, shape):
    """r = 1, three beacons (one near the window's end): P(K=0) + int p(T1) dT1 = 1."""
    model = _model(
        toa_sigma_s=2.0,
        clutter_rate=0.7,
        multipath_fraction=multipath,
        multipath_delay_s=5.0,
        multipath_delay_shape=shape,
    )
    mu, w = np.array([8.0, 14.0, 39.0]), 40.0
    p0 = np.exp(_loglik(mu, 0.8, [], 1, w, model))
    p1, _ = integrate.quad(lambda t: np.exp(_loglik(mu, 0.8, [t], 1, w, model)), 0, w, points=list(mu), limit=200)
    assert p0 + p1 == pytest.approx(1.0, abs=1e-7)


def test_likelihood_integrates_to_one_r2():
    """r = 2, two beacons: P(K=0) + int p(T1) + int int_{T1<T2} p(T1, T2) = 1."""
    model = _model(toa_sigma_s=1.5, clutter_rate=1.3)
    mu, w, pd = np.array([6.0, 12.0]), 20.0, 0.75
    p0 = np.exp(_loglik(mu, pd, [], 2, w, model))
    p1, _ = integrate.quad(lambda t: np.exp(_loglik(mu, pd, [t], 2, w, model)), 0, w, points=list(mu))
    p2, _ = integrate.dblquad(
        lambda t2, t1: np.exp(_loglik(mu, pd, [t1, t2], 2, w, model)), 0, w, lambda t1: t1, w, epsabs=1e-9
    )
    assert p0 + p1 + p2 == pytest.approx(1.0, abs=1e-6)


@pytest.mark.parametrize("shape", [1, 2])
def test_likelihood_with_echoes_integrates_to_one_r2(shape):
    """r = 2, two beacons, echoes (40%) and multipath, exponential or Erlang-2 delays:
    P(K=0) + int p(T1) + int int p(T1, T2) = 1."""
    model = _model(
        toa_sigma_s=1.5,
        clutter_rate=1.3,
        multipath_fraction=0.1,
        multipath_delay_s=3.0,
        multipath_delay_shape=shape,
        echo_fraction=0.4,
    )
    mu, w, pd = np.array([6.0, 12.0]), 20.0, 0.75
    p0 = np.exp(_loglik(mu, pd, [], 2, w, model))
    p1, _ = integrate.quad(lambda t: np.exp(_loglik(mu, pd, [t], 2, w, model)), 0, w, points=list(mu), limit=200)
    p2, _ = integrate.dblquad(
        lambda t2, t1: np.exp(_loglik(mu, pd, [t1, t2], 2, w, model)), 0, w, lambda t1: t1, w, epsabs=1e-9
    )
    assert p0 + p1 + p2 == pytest.approx(1.0, abs=1e-6)


@pytest.mark.parametrize("n_signals", [2, 4])  # partial windows (horizon W) and full ones (the last TOA)
def test_a_batch_of_windows_has_each_window_s_factors(n_signals):
    """Windows stacked one per particle (toa (P, K)) get the factors, shared term and echo
    terms each would get alone."""
    model = _model(toa_sigma_s=2.0, clutter_rate=1.5, multipath_fraction=0.1, echo_fraction=0.05)
    rng = np.random.default_rng(7)
    mu = rng.uniform(100.0, 3000.0, (5, 3))
    p_detect = rng.uniform(0.3, 0.9, (5, 3))
    toa = np.sort(rng.uniform(0.0, model.window_s, (5, n_signals)), axis=1)
    kwargs = {"max_signals": 4, "window_s": model.window_s, "model": model}
    batch = m.association_factors(mu, p_detect, toa, **kwargs)
    for p in range(5):
        alone = m.association_factors(mu[p : p + 1], p_detect[p : p + 1], toa[p], **kwargs)
        np.testing.assert_array_equal(batch.log_match[p], alone.log_match[0])
        np.testing.assert_array_equal(batch.log_unheard[p], alone.log_unheard[0])
        np.testing.assert_array_equal(batch.log_echo[p], alone.log_echo)
        assert batch.log_base[p] == alone.log_base


def test_ranking_penalises_a_beacon_predicted_early_but_not_stored():
    """A full window whose TOAs all come after beacon 0's prediction: positions that put
    beacon 0 early are unlikely under the ranked model, indifferent under the baseline."""
    model = _model(toa_sigma_s=1.0, clutter_rate=0.1, multipath_fraction=0.0)
    toas = [50.0, 60.0]
    early = np.array([10.0, 50.0, 60.0])  # beacon 0 should have been stored first
    late = np.array([90.0, 50.0, 60.0])  # beacon 0 arrives after the last stored TOA
    ranked_gap = _loglik(late, 0.9, toas, 2, 100.0, model) - _loglik(early, 0.9, toas, 2, 100.0, model)
    unranked_gap = _loglik(late, 0.9, toas, 2, 100.0, model, ranked=False) - _loglik(
        early, 0.9, toas, 2, 100.0, model, ranked=False
    )
    assert ranked_gap > np.log(5.0)  # missing a detectable early signal costs ~log(1 / (1 - Pd))
    assert unranked_gap == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize(("eps", "shape"), [(0.0, 1), (0.3, 1), (0.3, 2)])
def test_toa_density_and_cdf_agree(eps, shape):
    """f integrates to 1 and F is its integral, with and without the multipath tail."""
    model = _model(toa_sigma_s=2.0, multipath_fraction=eps, multipath_delay_s=15.0, multipath_delay_shape=shape)

    def density(r):
        return np.exp(m.toa_logpdf(np.array(r), model))

    assert integrate.quad(density, -50, 400, limit=200)[0] == pytest.approx(1.0, abs=1e-8)
    assert m.toa_cdf(np.array(7.0), model) == pytest.approx(integrate.quad(density, -50, 7.0, limit=200)[0], abs=1e-8)


def test_toa_density_of_an_array_is_its_values_one_by_one():
    """An array of residuals, whatever its shape and layout (a transposed view here), gives
    each value's density and CDF as if it were alone, in the array's shape."""
    model = _model(toa_sigma_s=2.0, multipath_fraction=0.2, multipath_delay_s=10.0, multipath_delay_shape=2)
    resid = np.random.default_rng(5).normal(0.0, 15.0, size=(4, 3)).T
    for evaluate in (m.toa_logpdf, m.toa_cdf):
        values = evaluate(resid, model)
        assert values.shape == (3, 4)
        alone = [[float(evaluate(np.array(r), model)) for r in row] for row in resid]
        assert np.array_equal(values, np.array(alone))


@pytest.mark.parametrize("shape", [1, 2])
@pytest.mark.parametrize(("sigma", "eps", "tau"), [(2.0, 0.1, 20.0), (1.0, 0.3, 5.0), (5.0, 0.2, 8.0)])
def test_toa_density_is_the_gaussian_delay_convolution(sigma, eps, tau, shape):
    """f(r) = (1 - eps) N(r; 0, sigma^2) + eps int_0^inf Gamma(d; k, tau / k) N(r - d; 0, sigma^2) dd,
    the integral by quadrature over scipy's densities, from 8 sds below the prediction to
    50 mean delays after it; F(r) the same law's probability by quadrature of that f."""
    model = _model(toa_sigma_s=sigma, multipath_fraction=eps, multipath_delay_s=tau, multipath_delay_shape=shape)

    theta = tau / shape
    # scipy.stats' densities written out (each quadrature calls them ~10^5 times: scipy's
    # per-call overhead made this test take minutes), checked against them once below
    log_gamma_norm = -math.lgamma(shape) - shape * math.log(theta)

    def gamma_pdf(d: float) -> float:
        return math.exp((shape - 1) * math.log(d) - d / theta + log_gamma_norm) if d > 0 else 0.0

    def norm_pdf(x: float) -> float:
        return math.exp(-0.5 * (x / sigma) ** 2) / (sigma * math.sqrt(2.0 * math.pi))

    for x in (0.3 * tau, 2.0 * tau):
        assert gamma_pdf(x) == pytest.approx(stats.gamma.pdf(x, shape, scale=theta), rel=1e-12)
        assert norm_pdf(x) == pytest.approx(stats.norm.pdf(x, scale=sigma), rel=1e-12)

    def density(r: float) -> float:
        def delayed(d: float) -> float:
            return gamma_pdf(d) * norm_pdf(r - d)

        lo, hi = max(r - 12 * sigma, 0.0), max(r + 12 * sigma, 0.0)  # where the Gaussian factor lives
        tail = integrate.quad(delayed, lo, hi, epsabs=0.0, epsrel=1e-11, limit=400)[0] if hi > lo else 0.0
        return (1 - eps) * norm_pdf(r) + eps * tail

    for r in np.r_[-8 * sigma, -2 * sigma, 0.0, 0.7 * sigma, 3 * sigma, tau / 2, tau, 4 * tau, 50 * tau]:
        assert np.exp(m.toa_logpdf(np.array(r), model)) == pytest.approx(density(r), rel=1e-8)
    for r in (-2 * sigma, 0.0, tau, 5 * tau):
        f_r = integrate.quad(density, -20 * sigma, r, epsabs=1e-13, limit=400, points=[0.0] if r > 0 else None)[0]
        assert m.toa_cdf(np.array(r), model) == pytest.approx(f_r, abs=1e-10)


@pytest.mark.parametrize("shape", [1, 2])
def test_delay_law_draws_density_and_cdf_agree(shape):
    """Draws of `multipath_delays` have mean tau and variance tau^2 / k; `delay_cdf` is the
    integral of exp(log(1 / theta) - d / theta + `delay_log_shape`) and matches the draws'
    empirical CDF; with k = 1 the draws are tau times the generator's exponential draws."""
    model = _model(multipath_delay_s=24.0, multipath_delay_shape=shape)
    theta = 24.0 / shape
    draws = m.multipath_delays(np.random.default_rng(5), model, 200_000)
    assert draws.mean() == pytest.approx(24.0, rel=0.01)
    assert draws.var() == pytest.approx(24.0**2 / shape, rel=0.02)

    def density(d: float) -> float:
        return float(np.exp(-np.log(theta) - d / theta + m.delay_log_shape(np.array(d), model)))

    for d in (3.0, 12.0, 40.0, 100.0):
        assert m.delay_cdf(np.array(d), model) == pytest.approx(integrate.quad(density, 0.0, d)[0], abs=1e-12)
        assert m.delay_cdf(np.array(d), model) == pytest.approx(np.mean(draws <= d), abs=0.005)
    assert m.delay_cdf(np.array(-1.0), model) == 0.0
    if shape == 1:
        np.testing.assert_array_equal(draws, 24.0 * np.random.default_rng(5).standard_exponential(200_000))


def test_predicted_arrival_by_hand():
    """mu = offset + drift * days since start + range / c + float clock offset."""
    beacons = BeaconTable(
        beacon_id=np.array(["A"], dtype=object),
        lat=np.array([-58.0]),
        lon=np.array([-100.0]),
        offset_s=np.array([300.0]),
        drift_s_per_day=np.array([0.01]),
        start=np.array([np.datetime64("2009-01-01T00:00", "ns")]),
        end=np.array([NAT]),
    )
    info = FloatInfo(
        float_id="f",
        launch_time=np.datetime64("2009-01-11T00:00", "ns"),
        launch_lat=-57.0,
        launch_lon=-101.0,
        end_time=np.datetime64("2009-01-21T00:00", "ns"),
        end_lat=np.nan,
        end_lon=np.nan,
        clock_offset_start_s=1.0,
        clock_offset_end_s=-3.0,
        window_s=4000.0,
        max_signals=4,
    )
    model = _model(sound_speed_m_s=1480.0)
    t = np.datetime64("2009-01-16T00:00", "ns")  # 15 days after start, half-way launch -> end
    wb = m.window_beacons(beacons, info, t)
    mu = m.predicted_toa_s(m.beacon_ranges_m(np.array([-57.0]), np.array([-101.0]), wb), wb, model)
    rng_m = Geodesic.WGS84.Inverse(-57.0, -101.0, -58.0, -100.0)["s12"]
    assert mu[0, 0] == pytest.approx(300.0 + 0.01 * 15 + rng_m / 1480.0 + (-1.0), abs=0.01)
    # Not yet active before its start date.
    assert len(m.window_beacons(beacons, info, np.datetime64("2008-12-31", "ns")).index) == 0


def _wb(n: int, **per_beacon) -> m.WindowBeacons:
    return m.WindowBeacons(np.arange(n), np.zeros(n), np.zeros(n), np.zeros(n), **per_beacon)


def test_detection_falls_off_with_range():
    model = _model(p_detect=0.9, detection_range_km=1000.0, detection_falloff_km=50.0)
    pd_ = m.detection_prob(np.array([[0.0, 1000e3, 2000e3]]), _wb(3), model)[0]
    assert pd_[0] == pytest.approx(0.9, rel=1e-6)
    assert pd_[1] == pytest.approx(0.45)
    assert pd_[2] < 1e-6
    assert np.all(m.detection_prob(np.array([[5e6]]), _wb(1), _model(p_detect=0.9)) == 0.9)


def test_per_beacon_detection_and_sound_speed_override_the_model():
    """Calibrated per-beacon values replace the model's; NaN keeps the model's."""
    model = _model(p_detect=0.9, detection_range_km=1000.0, detection_falloff_km=50.0, sound_speed_m_s=1480.0)
    wb = _wb(2, p_detect=np.array([0.5, np.nan]), detection_range_km=np.array([np.nan, 600.0]),
             sound_speed_m_s=np.array([1500.0, np.nan]))  # fmt: skip
    pd_ = m.detection_prob(np.array([[1000e3, 600e3]]), wb, model)[0]
    assert pd_ == pytest.approx([0.25, 0.45])
    mu = m.predicted_toa_s(np.array([[1500e3, 1480e3]]), wb, model)[0]
    assert mu == pytest.approx([1000.0, 1000.0])


def test_labeled_loglik_ignores_clutter_labels():
    model = _model(toa_sigma_s=2.0)
    mu = np.array([[10.0, 30.0]])
    ll = m.labeled_loglik(mu, np.array([11.0, 20.0]), np.array([0, -1]), model)
    assert ll[0] == pytest.approx(m.toa_logpdf(np.array(1.0), model))
