"""Posterior summaries: the paper's mean-parameter estimate, the leg table, bands, ESS."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rafostrack.legs.model import Legs
from rafostrack.legs.sampler import Chain
from rafostrack.legs.summaries import credible_band, leg_table, mean_track, paper_estimate, sample_ess


def _chain(samples):
    return Chain(
        tuple(samples),
        np.zeros(len(samples)),
        np.array([s.n_legs for s in samples]),
        np.zeros(len(samples), dtype=int),
        samples[0],
        0.0,
        {},
        {},
        0.0,
    )


def test_paper_estimate_is_the_trajectory_of_the_mean_parameters():
    a = Legs.from_parameters((0, 0), 0.0, 30.0, [10.0, 12.0], [0.1, 3.1], [10.0])
    b = Legs.from_parameters((2, 0), 0.0, 30.0, [14.0, 12.0], [0.3, -3.1], [20.0])
    est = paper_estimate(_chain([a, b]))
    np.testing.assert_allclose(est.knots[0], [1, 0])
    np.testing.assert_allclose(est.speeds, [12, 12])
    np.testing.assert_allclose(est.cuts, [0, 15, 30])
    assert abs(est.headings[1]) == pytest.approx(math.pi, abs=1e-9)  # circular mean across +-pi
    with pytest.raises(ValueError):
        paper_estimate(_chain([a, Legs(np.array([0.0, 30.0]), np.array([[0.0, 0.0], [1.0, 1.0]]))]))


def test_leg_table_of_a_constant_chain_has_no_spread():
    legs = Legs.from_parameters((0, 0), 0.0, 30.0, [2.0, 1.0], [0.0, math.pi / 2], [10.0])
    table = leg_table(_chain([legs] * 5))
    np.testing.assert_allclose(table["speed"], [2, 1])
    np.testing.assert_allclose(table["speed_lo"], table["speed_hi"])
    np.testing.assert_allclose(table["heading_rad"], [0, math.pi / 2], atol=1e-12)
    np.testing.assert_allclose(table[["start", "start_lo", "start_hi"]].to_numpy()[1], [10, 10, 10])
    np.testing.assert_allclose(mean_track(_chain([legs] * 3), np.array([5.0])), [[10, 0]])


def test_leg_table_intervals_cover_the_samples():
    rng = np.random.default_rng(0)
    samples = [Legs.from_parameters((0, 0), 0.0, 30.0, [2 + rng.normal(0, 0.1), 1.0], [0.0, 1.0], [10 + rng.normal()])
               for _ in range(400)]  # fmt: skip
    table = leg_table(_chain(samples), samples[0])
    assert table["start_lo"][1] < 10 < table["start_hi"][1]
    assert table["speed_lo"][0] < table["speed"][0] < table["speed_hi"][0]


def test_bands_and_effective_sample_size():
    rng = np.random.default_rng(1)
    iid = rng.normal(size=(4000, 3))
    lo, hi = credible_band(iid)
    assert np.all(lo < -1.8) and np.all(hi > 1.8)
    assert np.all(sample_ess(iid) > 2000)
    sticky = np.repeat(rng.normal(size=(40, 3)), 100, axis=0)  # 40 distinct values, 100 copies each
    assert np.all(sample_ess(sticky) < 200)
