"""One step's prior pi_0, the pseudo-likelihood f and the ABC distance (rafostrack.sensors.prior)."""

from __future__ import annotations

import numpy as np
import pytest

from rafostrack.sensors.prior import StepPrior, distances, log_pseudo_likelihood
from rafostrack.sensors.sensors import sensor_grid, simulate_counts


def make_prior() -> StepPrior:
    x_prev = np.array([[[0.0, 0.0], [10.0, -5.0]], [[3.0, 3.0], [-8.0, 1.0]]])  # (B = 2, Nt = 2, 2)
    v_prev = np.array([[[1.0, 0.0], [0.0, -2.0]], [[-1.0, 1.0], [2.0, 2.0]]])
    return StepPrior(x_prev, v_prev, 0.5)


def test_prior_draws_around_the_previous_velocity():
    prior = make_prior()
    theta = prior.sample(20_000, 3, np.random.default_rng(0))
    assert theta.shape == (20_000, 2, 3, 2, 2)
    np.testing.assert_allclose(theta.mean(axis=(0, 2)), prior.v_prev, atol=0.02)
    np.testing.assert_allclose(theta.std(axis=(0, 2)), 0.5, rtol=0.02)
    np.testing.assert_allclose(prior.positions(theta)[:, :, 0], prior.x_prev + theta[:, :, 0])


def test_prior_log_density_is_gaussian_up_to_a_constant():
    prior = make_prior()
    theta = prior.sample(5, 1, np.random.default_rng(1))
    z2 = (((theta - prior.v_prev[:, None]) / 0.5) ** 2).sum(axis=(-2, -1))
    np.testing.assert_allclose(prior.log_density(theta), -0.5 * z2)


def test_pseudo_likelihood_penalises_turns_and_speed_changes():
    v_prev = np.array([[[2.0, 0.0]]])
    straight = np.array([[[[2.0, 0.0]]]])
    assert log_pseudo_likelihood(straight, v_prev, 0.5)[0, 0] == pytest.approx(0.0)
    left = np.array([[[[0.0, 2.0]]]])
    right = np.array([[[[0.0, -2.0]]]])
    s_b = 0.5 / 2.0  # sd of the bearing: sigma / |v|
    expected = -0.5 * (np.pi / 2 / s_b) ** 2
    assert log_pseudo_likelihood(left, v_prev, 0.5)[0, 0] == pytest.approx(expected)
    assert log_pseudo_likelihood(right, v_prev, 0.5)[0, 0] == pytest.approx(expected)
    faster = np.array([[[[3.0, 0.0]]]])
    assert log_pseudo_likelihood(faster, v_prev, 0.5)[0, 0] == pytest.approx(-0.5 * (1.0 / 0.5) ** 2)
    assert log_pseudo_likelihood(faster, v_prev, 0.5, f_scale=2.0)[0, 0] == pytest.approx(-0.5 * (1.0 / 1.0) ** 2)


def test_distances_are_squared_count_differences_of_simulations():
    prior = make_prior()
    sensors = sensor_grid(16)
    counts = np.array([np.arange(16) % 3, np.arange(16) % 2])
    theta = prior.sample(7, 2, np.random.default_rng(2))
    rho = distances(theta, prior, counts, sensors, 0.9, np.random.default_rng(3))
    sim = simulate_counts(prior.positions(theta), theta, sensors, 0.9, np.random.default_rng(3))
    np.testing.assert_array_equal(rho, ((sim - counts[:, None]) ** 2).sum(axis=-1))
    assert rho.shape == (7, 2, 2)
