"""A leg fit as tables: units, compass bearings, times, and the float's position per window."""

from __future__ import annotations

import numpy as np
import pytest

from rafostrack.domain import Window
from rafostrack.legs.evidence import Grids, float_evidence
from rafostrack.legs.fit import LegFit
from rafostrack.legs.model import LegPrior, Legs
from rafostrack.legs.outputs import bearing_deg, float_positions, legs_frame, to_time
from rafostrack.legs.plane import Plane
from rafostrack.legs.sampler import Chain


def _fit(wiggle: tuple[float, ...] = (0.0,)) -> LegFit:
    """Two samples of two legs (east 10 km/day for 2 days, then north 5 km/day), windows at days 1, 2, 3."""
    a = Legs(np.array([0.0, 2.0, 4.0]), np.array([[0.0, 0.0], [20.0, 0.0], [20.0, 10.0]]))
    b = Legs(np.array([0.0, 2.0, 4.0]), np.array([[0.0, 2.0], [20.0, 2.0], [20.0, 12.0]]))
    chain = Chain((a, b), np.zeros(2), np.array([2, 2]), np.zeros(2, dtype=np.int64), a, 0.0, {}, {}, 0.0)
    days = np.array([1.0, 2.0, 3.0])
    offsets = np.arange(-5, 6, dtype=float)
    de, dn = np.meshgrid(offsets, offsets, indexing="ij")
    centres = np.array([[10.0, 1.0], [20.0, 1.0], [20.0, 6.0]])
    grids = Grids(centres, 1.0, np.stack([-0.5 * (de**2 + dn**2)] * 3))
    evidence = float_evidence(days, grids, [], 3.0, wiggle)
    windows = tuple(Window(np.datetime64("2010-01-02") + np.timedelta64(int(d) - 1, "D"), np.zeros(1)) for d in days)
    epoch = np.datetime64("2010-01-01T00:00", "ns")
    return LegFit("f9", epoch, Plane(-57.0, -100.0), windows, days, evidence, chain, a, LegPrior(), None, {})  # type: ignore[arg-type]


def test_bearings_and_times():
    np.testing.assert_allclose(bearing_deg(np.array([0.0, np.pi / 2, np.pi, -np.pi / 2])), [90, 0, 270, 180])
    assert to_time(_fit(), 1.5) == np.datetime64("2010-01-02T12:00", "ns")


def test_legs_frame_units_and_intervals():
    frame = legs_frame(_fit())
    assert list(frame["leg"]) == [1, 2]
    np.testing.assert_allclose(frame["speed_km_per_day"], [10.0, 5.0])
    np.testing.assert_allclose(frame["heading_deg"], [90.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(frame["duration_days"], [2.0, 2.0])
    assert frame["end"].iloc[0] == frame["start"].iloc[1] == np.datetime64("2010-01-03", "ns")


def test_float_position_is_the_leg_without_wiggle_and_pulled_towards_the_window_with_it():
    mean, cov = float_positions(_fit())
    np.testing.assert_allclose(mean, [[10, 1], [20, 1], [20, 6]])  # the mean of the two samples' legs
    np.testing.assert_allclose(cov[:, 1, 1], 2.0)  # the samples differ by 2 km north (sample variance)
    fit = _fit((0.0, 1.0))
    fit.chain.levels[:] = 1  # s = 1 km: the window (sd 1 km about its centre) pulls halfway
    mean, _ = float_positions(fit)
    np.testing.assert_allclose(mean, [[10, 1], [20, 1], [20, 6]], atol=1e-6)
    assert float_positions(fit)[1][0, 0, 0] == pytest.approx(0.5, abs=5e-3)  # grid spacing = s: discretised
