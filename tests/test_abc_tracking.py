"""The tracking loop of the ABC paper and its scores (rafostrack.sensors.tracking)."""

from __future__ import annotations

import numpy as np
import pytest

from rafostrack.sensors.prior import StepPrior, distances
from rafostrack.sensors.sensors import sensor_grid, simulate_truth
from rafostrack.sensors.tracking import (
    ALGORITHMS,
    Settings,
    expected_distance,
    initial_estimates,
    paper_tolerance,
    rmse,
    track,
)


def test_tolerance_rules():
    assert paper_tolerance(64, 2, 0.95) == pytest.approx(64 * 0.1**2)
    assert expected_distance(64, 2, 0.95) == pytest.approx(2 * 64 * 2 * 0.95 * 0.05)


def test_expected_distance_is_the_mean_distance_at_the_truth():
    sensors = sensor_grid(16)
    truth = simulate_truth(400, 3, sensors, 0.9, np.random.default_rng(0), steps=1)
    prior = StepPrior(truth.x[:, 0], truth.v[:, 1], 1.0)
    theta = truth.v[None, :, 1, None]  # the true step, (1, B, 1, Nt, 2)
    rho = distances(theta, prior, truth.counts[:, 1], sensors, 0.9, np.random.default_rng(1))
    expected = expected_distance(16, 3, 0.9)
    assert rho.mean() == pytest.approx(expected, rel=0.05)


def test_rmse():
    x_true = np.zeros((1, 2, 2, 2))
    x_hat = np.zeros_like(x_true)
    x_hat[0, 1, 0] = [3.0, 4.0]  # one of two targets 5 off
    np.testing.assert_allclose(rmse(x_hat, x_true), [[0.0, np.sqrt(12.5)]])


@pytest.mark.parametrize("algorithm", ALGORITHMS)
def test_every_algorithm_tracks_better_than_dead_reckoning(algorithm):
    sensors = sensor_grid(64)
    rng = np.random.default_rng(7)
    truth = simulate_truth(24, 1, sensors, 0.95, rng, steps=20)
    x0, v0 = initial_estimates(truth, rng)
    settings = Settings(algorithm, particles=100, keep=5)
    result = track(truth, sensors, x0, v0, settings, np.random.default_rng(8))
    assert result.x_hat.shape == (24, 21, 1, 2)
    np.testing.assert_allclose(np.diff(result.x_hat, axis=1), result.v_hat[:, 1:])
    assert len(result.samples) == 20 and result.samples[0].shape == (24, 5, 1, 2)
    dead_reckoning = x0[:, None] + np.arange(21)[None, :, None, None] * v0[:, None]
    ours, baseline = rmse(result.x_hat, truth.x)[:, -1].mean(), rmse(dead_reckoning, truth.x)[:, -1].mean()
    assert ours < 0.75 * baseline, (ours, baseline)
    assert 0 < result.acceptance.mean() < 1
    again = track(truth, sensors, x0, v0, settings, np.random.default_rng(8))
    np.testing.assert_array_equal(again.x_hat, result.x_hat)  # bit for bit


def test_settings_check_the_algorithm():
    with pytest.raises(ValueError, match="algorithm"):
        Settings("smc")
    assert Settings("pt", particles=300).simulations_per_step() == 1500
