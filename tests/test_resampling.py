from __future__ import annotations

import numpy as np
import pytest
from scipy.special import logsumexp

from rafostrack.filtering.resampling import (
    _inverse_cdf,
    ess,
    log_sum_exp,
    normalise_log_weights,
    quantile_points,
    systematic,
)


def test_systematic_copies_each_particle_floor_or_ceil_times():
    rng = np.random.default_rng(3)
    for _ in range(50):
        w = rng.dirichlet(np.full(40, 0.3))
        counts = np.bincount(systematic(w, rng), minlength=40)
        assert counts.sum() == 40
        assert np.all(counts >= np.floor(40 * w) - 1e-9) and np.all(counts <= np.ceil(40 * w) + 1e-9)


def test_systematic_is_unbiased():
    rng = np.random.default_rng(4)
    w = np.array([0.05, 0.15, 0.3, 0.5])
    mean = np.mean([np.bincount(systematic(w, rng), minlength=4) for _ in range(4000)], axis=0)
    assert np.allclose(mean / 4, w, atol=0.01)


def test_log_sum_exp_matches_scipy():
    """Against scipy's logsumexp: large magnitudes, -inf terms, zero and tiny scales, all
    terms zero."""
    rng = np.random.default_rng(5)
    for _ in range(200):
        log_w = rng.normal(0.0, 300.0, size=50) - 1e4 * rng.integers(0, 2)
        log_w[rng.random(50) < 0.2] = -np.inf
        scale = rng.dirichlet(np.full(50, 0.2))
        scale[rng.random(50) < 0.2] = 0.0
        assert log_sum_exp(log_w) == pytest.approx(logsumexp(log_w), rel=1e-13, abs=1e-10)
        assert log_sum_exp(log_w, scale) == pytest.approx(logsumexp(log_w, b=scale), rel=1e-13, abs=1e-10)
    assert log_sum_exp(np.full(3, -np.inf)) == -np.inf
    assert log_sum_exp(np.zeros(3), np.zeros(3)) == -np.inf


def test_log_weights_survive_huge_magnitudes():
    w, log_sum = normalise_log_weights(np.array([-1e5, -1e5 + np.log(3.0)]))
    assert np.allclose(w, [0.25, 0.75])
    assert log_sum == pytest.approx(-1e5 + np.log(4.0))


def test_ess_bounds():
    assert ess(np.full(10, 0.1)) == pytest.approx(10.0)
    assert ess(np.eye(1, 10)[0]) == pytest.approx(1.0)


def test_quantile_points_stand_for_the_weights():
    """Quantile points: at most n particles, weights summing to 1, each particle's weight
    within 1/n of its own; particles as they are when few carry the weight."""
    rng = np.random.default_rng(5)
    w = rng.gamma(0.3, size=5000)
    w /= w.sum()
    index, v = quantile_points(w, 400)
    assert len(index) <= 400 and np.isclose(v.sum(), 1.0) and np.all(np.diff(index) > 0)
    assert np.all(np.abs(v - w[index]) <= 1.0 / 400 + 1e-12)
    assert w[np.setdiff1d(np.arange(5000), index)].max() < 1.0 / 400
    few = np.zeros(5000)
    few[[3, 70, 900]] = [0.2, 0.3, 0.5]
    index, v = quantile_points(few, 400, prune=1e-14)
    assert index.tolist() == [3, 70, 900] and np.allclose(v, [0.2, 0.3, 0.5])


def test_inverse_cdf_is_numpy_searchsorted_on_sorted_points():
    """The merge search gives numpy's searchsorted (side "right") bit for bit: zero weights,
    ties between a point and a cumulative sum, points from every scheme."""
    rng = np.random.default_rng(5)
    for n in (1, 7, 1000):
        weights = rng.gamma(0.3, size=n) * (rng.random(n) > 0.3)
        weights = weights / weights.sum() if weights.sum() > 0 else np.full(n, 1.0 / n)
        cumulative = np.cumsum(weights)
        cumulative[-1] = 1.0
        ties = cumulative[cumulative < 1.0]  # points in [0, 1), as every scheme draws them
        for points in (np.sort(rng.random(n)), (rng.random() + np.arange(n)) / n, ties):
            assert np.array_equal(_inverse_cdf(weights, points), np.searchsorted(cumulative, points, side="right"))
