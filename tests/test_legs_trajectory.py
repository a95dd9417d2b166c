"""Positions and velocities along legs."""

from __future__ import annotations

import numpy as np

from rafostrack.legs.model import Legs
from rafostrack.legs.trajectory import leg_index, mean_velocities, positions, velocities

LEGS = Legs(np.array([0.0, 10.0, 30.0]), np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 40.0]]))


def test_positions_hit_the_knots_and_interpolate():
    np.testing.assert_allclose(positions(LEGS, np.array([0.0, 10.0, 30.0])), LEGS.knots)
    np.testing.assert_allclose(positions(LEGS, np.array([5.0, 20.0])), [[5, 0], [10, 20]])


def test_outside_the_span_the_end_legs_are_extended():
    np.testing.assert_allclose(positions(LEGS, np.array([-2.0, 31.0])), [[-2, 0], [10, 42]])


def test_velocities_and_mean_velocities():
    np.testing.assert_allclose(velocities(LEGS, np.array([1.0, 29.0])), [[1, 0], [0, 2]])
    np.testing.assert_allclose(
        mean_velocities(LEGS, np.array([0.0, 5.0]), np.array([30.0, 15.0])), [[1 / 3, 4 / 3], [0.5, 1.0]]
    )
    np.testing.assert_array_equal(
        leg_index(LEGS.cuts, np.array([-1.0, 0.0, 9.99, 10.0, 30.0, 99.0])), [0, 0, 0, 1, 1, 1]
    )
