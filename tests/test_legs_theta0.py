"""The paper's data-driven starting point."""

from __future__ import annotations

import numpy as np

from rafostrack.legs.model import LegPrior, Legs
from rafostrack.legs.scores import Measurements
from rafostrack.legs.theta0 import _nearest_index, data_driven_start, equal_legs
from rafostrack.legs.trajectory import positions


def test_noise_free_measurements_are_reproduced():
    truth = Legs.from_parameters((0, 0), 0.0, 100.0, [12.0, 10.0], [0.0, 1.0], [50.0])
    t = np.arange(0.0, 101.0, 5.0)
    data = Measurements(t, positions(truth, t))
    legs = data_driven_start(data, LegPrior())
    assert 100 / 40 <= legs.n_legs <= 100 / 5
    np.testing.assert_allclose(positions(legs, t), data.xy, atol=1e-9)


def test_equal_legs_uses_the_nearest_measurements_in_time():
    t = np.array([0.0, 4.0, 11.0, 20.0])
    xy = np.array([[0.0, 0.0], [4.0, 0.0], [11.0, 3.0], [20.0, 3.0]])
    legs = equal_legs(Measurements(t, xy), 2)  # cuts 0, 10, 20: nearest 0, 11, 20
    np.testing.assert_allclose(legs.cuts, [0, 10, 20])
    np.testing.assert_allclose(legs.knots, [[0, 0], [11, 3], [20, 3]])
    np.testing.assert_array_equal(_nearest_index(t, np.array([-5.0, 2.0, 7.6, 99.0])), [0, 0, 2, 3])


def test_only_guesses_the_prior_allows_are_kept():
    t = np.arange(0.0, 501.0, 1.0)
    data = Measurements(t, np.column_stack([t, 0 * t]))
    legs = data_driven_start(data, LegPrior(duration_min=5, duration_max=40))
    assert 5 <= legs.durations.min() and legs.durations.max() < 40
