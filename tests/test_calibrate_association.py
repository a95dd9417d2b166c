"""Multipath, echoes and clutter: the EM at a known track (`calibrate.association`) and the
timing fit's noise model (`calibrate.noise`), against simulated truth and closed forms.

Oracles: the simulator's generating values (the tracker's own model, so the EM's model is
the true one) and the complete-data clutter rate from the true labels; scipy's
exponentially modified Gaussian for the error density; numerical integration for the
delay's posterior mean."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy import integrate, stats

from rafostrack.calibrate.association import _delay_mean, fit_association
from rafostrack.calibrate.noise import (
    delay_posterior_mean_s,
    direct_probability,
    fit_clutter_rate,
    fit_multipath,
    fit_multipath_em,
)
from rafostrack.config import load_config
from rafostrack.domain import ArrivalRecord, Window
from rafostrack.mission.array_fit import MULTIPATH_TOLERANCE
from rafostrack.model.measurement import horizon_s, toa_logpdf
from rafostrack.sim.scenarios import synthetic_scenario
from rafostrack.sim.simulate import simulate_mission

MODEL = load_config().model
TRUE = dataclasses.replace(
    MODEL, toa_sigma_s=1.5, multipath_fraction=0.12, multipath_delay_s=30.0, echo_fraction=0.10, clutter_rate=2.0
)
# Starting values on either side of the truth.
LOW = dataclasses.replace(TRUE, multipath_fraction=0.02, multipath_delay_s=15.0, echo_fraction=0.01, clutter_rate=0.5)
HIGH = dataclasses.replace(TRUE, multipath_fraction=0.3, multipath_delay_s=60.0, echo_fraction=0.3, clutter_rate=5.0)


def _simulated(seed: int, days: int = 200):
    """200 daily windows of 8 beacons at the synthetic ring, 6 signals stored a window."""
    beacons, (info,) = synthetic_scenario(days=days, rng=seed)
    info = dataclasses.replace(info, max_signals=6)
    sim = simulate_mission(beacons, [info], TRUE, np.random.default_rng(seed)).floats[0]
    times = np.array([w.time for w in sim.record.windows], dtype="datetime64[ns]")
    at = sim.truth.set_index("time").loc[times]
    return beacons, sim, at["lat"].to_numpy(), at["lon"].to_numpy()


def _realised_clutter_rate(record: ArrivalRecord, max_signals: int, window_s: float) -> float:
    """Stored clutter signals (true labels) per window of exposure: a window stores clutter
    up to its horizon (its last TOA when full, else its end)."""
    count = sum(sum(b is None for b in w.beacon_id) for w in record.windows)
    exposure = sum(horizon_s(w.toa_s, max_signals, window_s) / window_s for w in record.windows)
    return count / exposure


@pytest.mark.parametrize("seed", [0, 1])
def test_em_at_the_true_track_recovers_multipath_echoes_and_clutter(seed):
    beacons, sim, lat, lon = _simulated(seed)
    fits = [fit_association(sim.record, lat, lon, beacons, sim.info, start, 0.5) for start in (LOW, HIGH)]
    realised = _realised_clutter_rate(sim.record, sim.info.max_signals, sim.info.window_s)
    for fitted, report in fits:
        assert abs(fitted.multipath_fraction - TRUE.multipath_fraction) < 0.03
        assert abs(fitted.multipath_delay_s / TRUE.multipath_delay_s - 1) < 0.2
        assert abs(fitted.echo_fraction - TRUE.echo_fraction) < 0.035
        assert abs(fitted.clutter_rate / realised - 1) < 0.12
        assert fitted.toa_sigma_s == TRUE.toa_sigma_s  # not fitted here
        assert report["e_step_toa_sigma_s"] == pytest.approx(np.hypot(1.5, 0.5 / 1.48), abs=1e-3)
        assert report["multipath_fraction"] == round(fitted.multipath_fraction, 4)
    # From either start the EM reaches about the same point (its 8 iterations stop short of
    # the fixed point by ~0.01 in the echo fraction and ~6% in tau: tau couples multipath
    # and echoes, which slows it).
    (low, _), (high, _) = fits
    assert abs(low.multipath_fraction - high.multipath_fraction) < 0.005
    assert abs(low.echo_fraction - high.echo_fraction) < 0.012
    assert abs(low.multipath_delay_s / high.multipath_delay_s - 1) < 0.08
    assert abs(low.clutter_rate / high.clutter_rate - 1) < 0.06


def test_em_learns_the_delay_scale_from_echoes_when_there_is_no_multipath():
    echo_only = dataclasses.replace(TRUE, multipath_fraction=0.0, echo_fraction=0.10)
    beacons, (info,) = synthetic_scenario(days=200, rng=9)
    info = dataclasses.replace(info, max_signals=6)
    sim = simulate_mission(beacons, [info], echo_only, np.random.default_rng(9)).floats[0]
    times = np.array([w.time for w in sim.record.windows], dtype="datetime64[ns]")
    at = sim.truth.set_index("time").loc[times]
    fitted, _ = fit_association(sim.record, at["lat"].to_numpy(), at["lon"].to_numpy(), beacons, sim.info, LOW, 0.5)
    assert fitted.multipath_fraction < 0.02
    assert abs(fitted.echo_fraction - 0.10) < 0.035
    # Echo delays are taken from the beacon's expected first-arrival time and are seen only
    # before the horizon: tau comes out 37.7 s here (30.0 on seed 7); without the echoes in
    # the M-step it wandered to ~119 s.
    assert abs(fitted.multipath_delay_s / 30.0 - 1) < 0.3
    realised = _realised_clutter_rate(sim.record, sim.info.max_signals, sim.info.window_s)
    assert abs(fitted.clutter_rate / realised - 1) < 0.12


@pytest.mark.parametrize(("sigma", "eps", "tau"), [(1.5, 0.1, 30.0), (2.0, 0.05, 60.0), (1.0, 0.2, 15.0)])
def test_error_density_and_direct_probability_match_the_exponnorm_mixture(sigma, eps, tau):
    """f(r) = (1 - eps) N(r; 0, sigma^2) + eps (N * Exp(mean tau))(r), the latter scipy's
    exponnorm(K = tau / sigma, scale = sigma); P(direct | r) by Bayes' rule."""
    model = dataclasses.replace(MODEL, toa_sigma_s=sigma, multipath_fraction=eps, multipath_delay_s=tau)
    r = np.linspace(-6 * sigma, 200.0, 801)
    direct = (1 - eps) * stats.norm.pdf(r, scale=sigma)
    delayed = eps * stats.exponnorm.pdf(r, tau / sigma, scale=sigma)
    np.testing.assert_allclose(np.exp(toa_logpdf(r, model)), direct + delayed, rtol=1e-9, atol=1e-300)
    np.testing.assert_allclose(direct_probability(r, model), direct / (direct + delayed), rtol=1e-8, atol=1e-12)


@pytest.mark.parametrize(("eps", "tau"), [(0.1, 30.0), (0.05, 80.0)])
def test_fit_multipath_recovers_the_mixture(eps, tau):
    """Residuals r = N(0, sigma^2) + [u < eps] Exp(tau), sigma known: maximum likelihood
    of (eps, tau) recovers them from 5000 draws, whatever the start."""
    rng = np.random.default_rng(11)
    n, sigma = 5000, 1.5
    r = sigma * rng.standard_normal(n) + np.where(rng.random(n) < eps, rng.exponential(tau, n), 0.0)
    for start_eps, start_tau in ((0.01, 10.0), (0.25, 150.0)):
        start = dataclasses.replace(MODEL, multipath_fraction=start_eps, multipath_delay_s=start_tau)
        got_eps, got_tau = fit_multipath(r, sigma, start)
        assert abs(got_eps - eps) < 0.015
        assert abs(got_tau / tau - 1) < 0.15


def test_the_array_fits_multipath_by_em_is_within_its_tolerance_of_the_fine_one():
    """At the array fit's tolerance (`MULTIPATH_TOLERANCE`) EM stops within about 1% of the
    calibration's Nelder-Mead optimum in eps and tau, and its direct-path weights differ by
    less than 0.01, whatever the start."""
    rng = np.random.default_rng(12)
    n, sigma, eps, tau = 3000, 1.5, 0.08, 40.0
    r = sigma * rng.standard_normal(n) + np.where(rng.random(n) < eps, rng.exponential(tau, n), 0.0)
    for start_eps, start_tau in ((0.01, 10.0), (0.25, 150.0), (0.08, 40.0)):
        start = dataclasses.replace(MODEL, multipath_fraction=start_eps, multipath_delay_s=start_tau)
        fine = fit_multipath(r, sigma, start)
        coarse = fit_multipath_em(r, sigma, start, MULTIPATH_TOLERANCE)
        np.testing.assert_allclose(coarse, fine, rtol=0.01)
        weights = [
            direct_probability(
                r, dataclasses.replace(MODEL, toa_sigma_s=sigma, multipath_fraction=e, multipath_delay_s=t)
            )
            for e, t in (fine, coarse)
        ]
        assert np.max(np.abs(weights[0] - weights[1])) < 0.01


@pytest.mark.parametrize("shape", [1, 2])
def test_em_reaches_nelder_meads_maximum(shape):
    """EM (`fit_multipath_em`) and Nelder-Mead, two optimisers, meet at the same maximum of
    the mixture's likelihood to 1e-3, for both delay laws and from starts on either side."""
    rng = np.random.default_rng(13)
    n, sigma, eps, tau = 4000, 1.5, 0.1, 30.0
    delay = rng.gamma(shape, tau / shape, n)
    r = sigma * rng.standard_normal(n) + np.where(rng.random(n) < eps, delay, 0.0)
    for start_eps, start_tau in ((0.02, 10.0), (0.25, 150.0)):
        start = dataclasses.replace(
            MODEL, multipath_fraction=start_eps, multipath_delay_s=start_tau, multipath_delay_shape=shape
        )
        by_nm = fit_multipath(r, sigma, start, (1e-7, 1e-9))
        by_em = fit_multipath_em(r, sigma, start, (1e-6, 0.0))
        np.testing.assert_allclose(by_em, by_nm, rtol=1e-3)


@pytest.mark.parametrize("shape", [1, 2])
def test_delay_posterior_mean_against_quadrature(shape):
    """E[d | r] of a delayed arrival (`delay_posterior_mean_s`) against the ratio of the
    integrals of d p(d, r) and p(d, r) over d > 0, p(d, r) = Gamma(d; k, tau / k) N(r - d;
    0, sigma^2), by numerical quadrature: early, central and late residuals."""
    sigma, tau = 1.5, 25.0
    model = dataclasses.replace(MODEL, toa_sigma_s=sigma, multipath_delay_s=tau, multipath_delay_shape=shape)
    residual = np.array([-40.0, -8.0, -1.0, 0.0, 2.0, 10.0, 60.0, 250.0])
    got = delay_posterior_mean_s(residual, model)
    for r, value in zip(residual, got, strict=True):

        def integral(power: int, r: float = r) -> float:
            """The integral of d^power p(d, r) over d > 0 (where the mass is: to r + 12 sigma)."""

            def integrand(d: float) -> float:
                return d**power * stats.gamma.pdf(d, shape, scale=tau / shape) * stats.norm.pdf(r - d, scale=sigma)

            peak = max(r, 0.0)
            top = peak + 12 * sigma
            return integrate.quad(integrand, 0.0, top, points=[peak], epsabs=0, epsrel=1e-12, limit=200)[0]

        np.testing.assert_allclose(value, integral(1) / integral(0), rtol=1e-6)


@pytest.mark.parametrize("shape", [1, 2])
@pytest.mark.parametrize(
    ("resid", "sigma", "tau"),
    [(0.0, 1.5, 30.0), (5.0, 1.5, 30.0), (40.0, 2.0, 20.0), (-3.0, 1.0, 50.0), (-12.0, 1.0, 10.0)],
)
def test_delay_mean_is_the_posterior_mean_of_the_delay(resid, sigma, tau, shape):
    """E[d | r] for r = g + d, g ~ N(0, sigma^2), d ~ Gamma(shape k, mean tau), by quadrature."""

    def weight(d):
        return stats.norm.pdf(resid - d, scale=sigma) * stats.gamma.pdf(d, shape, scale=tau / shape)

    hi = max(resid, 0.0) + 40 * sigma
    # breakpoints where the weight lives: at r, and within sigma^2 / |r| of 0 when r < 0 (a
    # weight of ~e^-70 there: relative tolerance only)
    points = sorted({max(resid, 0.0), 0.1 * sigma, sigma})
    norm = integrate.quad(weight, 0.0, hi, points=points, epsabs=0.0, epsrel=1e-12, limit=200)[0]
    mean = integrate.quad(lambda d: d * weight(d), 0.0, hi, points=points, epsabs=0.0, epsrel=1e-12, limit=200)[0]
    mean /= norm
    assert float(_delay_mean(np.array(resid), sigma, tau, shape)) == pytest.approx(mean, rel=1e-6, abs=1e-8)


def test_clutter_rate_counts_clutter_over_the_exposed_time():
    """lambda = sum of clutter probabilities / sum of (horizon / W): a full window is
    exposed up to its last TOA, a window with room to its end."""
    from rafostrack.domain import FloatInfo

    t = np.datetime64("2010-01-02", "ns")
    info = FloatInfo("f", t, -58.0, -90.0, np.datetime64("NaT", "ns"), np.nan, np.nan, 0.0, 0.0, 4000.0, 3)
    windows = (
        Window(t, np.array([100.0, 900.0, 2000.0])),  # full: exposed to 2000 s = 0.5 window
        Window(t, np.array([300.0])),  # room left: the whole window
        Window(t, np.zeros(0)),  # empty: the whole window
    )
    record = ArrivalRecord("f", None, windows)
    p_clutter = np.array([0.0, 1.0, 0.5, 1.0])
    assert fit_clutter_rate(p_clutter, record, info) == pytest.approx(2.5 / 2.5)
    assert fit_clutter_rate(np.array([0.0, 0.0, 1.0, 1.0]), record, info) == pytest.approx(2.0 / 2.5)
