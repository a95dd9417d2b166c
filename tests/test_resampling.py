from __future__ import annotations

import numpy as np
import pytest

from rafostrack.resampling import ess, normalise_log_weights, systematic


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


def test_log_weights_survive_huge_magnitudes():
    w, log_sum = normalise_log_weights(np.array([-1e5, -1e5 + np.log(3.0)]))
    assert np.allclose(w, [0.25, 0.75])
    assert log_sum == pytest.approx(-1e5 + np.log(4.0))


def test_ess_bounds():
    assert ess(np.full(10, 0.1)) == pytest.approx(10.0)
    assert ess(np.eye(1, 10)[0]) == pytest.approx(1.0)
