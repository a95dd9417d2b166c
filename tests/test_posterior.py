"""Summaries of weighted clouds (`rafostrack.summaries.posterior`)."""

from __future__ import annotations

import numpy as np
import pytest

from rafostrack.summaries.posterior import summarise, two_modes


def test_summarise_weighted_mean_and_spread():
    lat = np.array([-58.0, -58.0, -58.0 + 10 / 111.4])
    lon = np.array([-90.0, -90.0, -90.0])
    s = summarise(lat, lon, np.array([0.25, 0.25, 0.5]))
    assert s.lat == pytest.approx(-58.0 + 5 / 111.4, abs=1e-3)
    assert s.sd_km == pytest.approx(5.0, rel=0.01)  # half the mass 10 km north: sd 5 km


def test_a_posterior_parted_by_forbidden_ground_reports_its_heavier_region():
    """Particles on both sides of a ridge (region labels 0 and 1): the whole mean lies on the
    ridge, the reported position is the heavier side's mean; the sides are separate modes
    when the lighter holds min_weight, and still parted (not averaged) when it does not."""
    rng = np.random.default_rng(3)
    lat = np.r_[rng.normal(-58.0, 0.01, 700), rng.normal(-57.8, 0.01, 300)]
    lon = rng.normal(-60.0, 0.01, 1000)
    weights = np.full(1000, 1e-3)
    groups = np.r_[np.zeros(700, np.int64), np.ones(300, np.int64)]
    kw = {"min_separation_km": 10.0, "separation_factor": 2.0}
    modes = two_modes(lat, lon, weights, min_weight=0.05, groups=groups, **kw)
    assert modes.parted and modes.ambiguous and modes.first_weight == pytest.approx(0.7)
    assert modes.position.lat == pytest.approx(-58.0, abs=0.005)
    assert modes.whole.lat == pytest.approx(-57.94, abs=0.005)  # on the ridge between
    light = two_modes(lat, lon, weights, min_weight=0.5, groups=groups, **kw)
    assert light.parted and not light.ambiguous and light.position.lat == pytest.approx(-58.0, abs=0.005)
    one = two_modes(lat[:700], lon[:700], weights[:700], min_weight=0.05, groups=groups[:700], **kw)
    assert not one.parted and one.position is one.whole
