"""Reversible jump over K: without data it samples the renewal prior of K; with clear data
it finds the true number of legs."""

from __future__ import annotations

import numpy as np
import pytest

from rafostrack.legs.model import LegPrior, Legs, sample_prior
from rafostrack.legs.rjmcmc import merge, split
from rafostrack.legs.sampler import SamplerConfig, run_chain
from rafostrack.legs.scores import GaussianLikelihood, Measurements
from rafostrack.legs.theta0 import equal_legs
from rafostrack.legs.trajectory import positions

ALL_MOVES = {"leg": 1.0, "knot": 1.0, "shift": 1.0, "jump": 2.0}


class NoData:
    """A likelihood that says nothing: the chain must sample the prior."""

    times = np.array([0.0, 60.0])

    def terms(self, xy, index):
        return np.zeros(len(xy))


def test_without_data_k_follows_the_renewal_prior():
    prior = LegPrior(duration_min=5.0, duration_max=40.0)
    rng = np.random.default_rng(0)
    draws = np.array([sample_prior(prior, (0, 0), 0.0, 60.0, rng).n_legs for _ in range(6000)])
    want = np.bincount(draws, minlength=13)[1:13] / len(draws)
    start = Legs.from_parameters((0, 0), 0.0, 60.0, [12.5, 12.5], [0.0, 0.0], [30.0])
    config = SamplerConfig(iterations=20000, moves=ALL_MOVES, max_kept=20000, knot_step=60.0)
    chain = run_chain(NoData(), prior, start, config, np.random.default_rng(1), free_start=False)
    got = np.bincount(chain.n_legs, minlength=13)[1:13] / len(chain.samples)
    assert chain.acceptance["jump"] > 0.05
    np.testing.assert_allclose(got, want, atol=0.05)
    assert abs(chain.n_legs.mean() - draws.mean()) < 0.12


def test_split_then_merge_is_the_identity():
    legs = Legs(np.array([0.0, 10.0, 30.0]), np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 40.0]]))
    rng = np.random.default_rng(2)
    new, log_q, coords, a, b = split(legs, rng, 1.0, 10)
    assert new.n_legs == 3 and coords == "knot" and a < b
    # merging the inserted change time back: its log q is the split's, negated
    j = int(np.flatnonzero(~np.isin(new.cuts, legs.cuts))[0])

    class Fixed:
        def integers(self, lo, hi):
            return j

    back, log_q_back, *_ = merge(new, Fixed(), 1.0, 10)  # type: ignore[arg-type]
    np.testing.assert_allclose(back.cuts, legs.cuts)
    np.testing.assert_allclose(back.knots, legs.knots)
    assert log_q_back == pytest.approx(-log_q)


@pytest.mark.parametrize("n_true", [1, 3])
def test_clear_cases_recover_the_number_of_legs(n_true):
    prior = LegPrior(duration_min=5.0, duration_max=150.0, heading_change_sd_rad=1.5)
    headings = [0.0, np.pi / 2, np.pi][:n_true]
    truth = Legs.from_parameters((0, 0), 0.0, 100.0 * n_true, [12.5] * n_true, headings, [100.0] * (n_true - 1))
    t = np.arange(0.0, 100.0 * n_true + 1, 4.0)
    rng = np.random.default_rng(7)
    data = Measurements(t, positions(truth, t) + rng.normal(0, 3.0, (len(t), 2)))
    config = SamplerConfig(iterations=12000, moves={**ALL_MOVES, "start": 0.5}, knot_step=3.0)
    chain = run_chain(GaussianLikelihood(data, 3.0), prior, equal_legs(data, 6), config, np.random.default_rng(8))
    k = chain.n_legs
    assert np.bincount(k).argmax() == n_true
    assert np.mean(k == n_true) > 0.5
