"""The binary sensor network and target simulator of the ABC paper (rafostrack.sensors.sensors)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from rafostrack.sensors.sensors import (
    approaching,
    log_likelihood,
    reported_counts,
    sensor_grid,
    simulate_counts,
    simulate_targets,
    simulate_truth,
)


def test_sensor_grid_is_regular_and_centred():
    grid = sensor_grid(16)
    assert grid.shape == (16, 2)
    np.testing.assert_allclose(np.unique(grid[:, 0]), [-37.5, -12.5, 12.5, 37.5])
    np.testing.assert_allclose(grid.mean(axis=0), 0.0, atol=1e-12)
    with pytest.raises(ValueError, match="square"):
        sensor_grid(15)


def test_approaching_is_the_sign_of_the_inner_product():
    rng = np.random.default_rng(0)
    sensors = rng.uniform(-50, 50, (7, 2))
    x, v = rng.uniform(-50, 50, (5, 3, 2)), rng.normal(size=(5, 3, 2))
    a = approaching(x, v, sensors)
    assert a.shape == (5, 7, 3)
    for r, i, j in itertools.product(range(5), range(7), range(3)):
        assert a[r, i, j] == (np.dot(x[r, j] - sensors[i], v[r, j]) < 0)


def test_targets_start_on_the_circle_heading_for_the_centre_and_follow_eq1():
    rng = np.random.default_rng(1)
    x, v = simulate_targets(4000, 2, rng, steps=5, speed=2.0, velocity_var=0.1)
    assert x.shape == v.shape == (4000, 6, 2, 2)
    np.testing.assert_allclose(np.hypot(*np.moveaxis(x[:, 0], -1, 0)), 40.0)
    np.testing.assert_allclose(v[:, 0], -2.0 * x[:, 0] / 40.0)
    np.testing.assert_allclose(np.diff(x, axis=1), v[:, 1:])  # x_t = x_{t-1} + v_t
    dv = np.diff(v, axis=1).ravel()
    assert abs(dv.mean()) < 4 * np.sqrt(0.1 / dv.size)
    assert dv.var() == pytest.approx(0.1, rel=0.03)  # sigma^2 = 0.1


def test_reported_bits_are_flipped_with_probability_one_minus_pe():
    rng = np.random.default_rng(2)
    bits = np.zeros((200_000, 1), dtype=bool)
    rate = reported_counts(bits, 0.9, rng).mean()
    assert rate == pytest.approx(0.1, abs=4 * np.sqrt(0.09 / 200_000))


def _brute_force_pmf(a: np.ndarray, pe: float) -> dict[tuple[int, ...], float]:
    """P(counts) for one state with bits a (Ns, Nt), enumerating every flip pattern."""
    ns, nt = a.shape
    out: dict[tuple[int, ...], float] = {}
    for flips in itertools.product([0, 1], repeat=ns * nt):
        f = np.array(flips, dtype=bool).reshape(ns, nt)
        p = float(np.prod(np.where(f, 1 - pe, pe)))
        key = tuple((a ^ f).sum(axis=1))
        out[key] = out.get(key, 0.0) + p
    return out


@pytest.mark.parametrize("n_targets", [1, 2, 3])
def test_log_likelihood_matches_enumeration(n_targets):
    rng = np.random.default_rng(3 + n_targets)
    sensors = rng.uniform(-20, 20, (3, 2))
    x, v = rng.uniform(-20, 20, (n_targets, 2)), rng.normal(size=(n_targets, 2))
    pe = 0.8
    pmf = _brute_force_pmf(approaching(x, v, sensors), pe)
    assert sum(pmf.values()) == pytest.approx(1.0)
    counts = np.array(list(itertools.product(range(n_targets + 1), repeat=3)))
    logp = log_likelihood(counts, x[None], v[None], sensors, pe)
    expected = np.array([pmf.get(tuple(c), 0.0) for c in counts])
    np.testing.assert_allclose(np.exp(logp), expected, rtol=1e-12, atol=1e-300)


def test_eq6_for_one_target():
    sensors = sensor_grid(4, 10.0)
    x, v = np.array([[1.0, 2.0]]), np.array([[1.0, 0.0]])
    a = approaching(x, v, sensors)[:, 0]  # sensors to the right (x = 5) see it coming
    np.testing.assert_array_equal(a, [False, True, False, True])
    c = np.array([0, 1, 0, 0])
    pe = 0.9
    expected = np.log(pe) * 3 + np.log(1 - pe)  # sensor 3 is wrong
    assert log_likelihood(c, x, v, sensors, pe) == pytest.approx(expected)


def test_simulated_counts_follow_the_likelihood():
    rng = np.random.default_rng(5)
    sensors = np.array([[0.0, 10.0], [5.0, -5.0]])
    x, v = np.array([[1.0, 1.0], [-3.0, 2.0]]), np.array([[0.5, 1.0], [1.0, -0.2]])
    n = 100_000
    sims = simulate_counts(np.broadcast_to(x, (n, 2, 2)), np.broadcast_to(v, (n, 2, 2)), sensors, 0.85, rng)
    for c in itertools.product(range(3), repeat=2):
        p = float(np.exp(log_likelihood(np.array(c), x, v, sensors, 0.85)))
        freq = np.mean((sims == np.array(c)).all(axis=1))
        assert abs(freq - p) < 5 * np.sqrt(p * (1 - p) / n) + 1e-9, c


def test_simulate_truth_is_reproducible():
    sensors = sensor_grid(16)
    a = simulate_truth(3, 2, sensors, 0.95, np.random.default_rng(9))
    b = simulate_truth(3, 2, sensors, 0.95, np.random.default_rng(9))
    np.testing.assert_array_equal(a.x, b.x)
    np.testing.assert_array_equal(a.counts, b.counts)
    assert a.steps == 30 and a.counts.shape == (3, 31, 16)
    assert a.counts.max() <= 2 and (a.counts[:, 0] == 0).all()
