"""Summaries of weighted clouds (`rafostrack.posterior`)."""

from __future__ import annotations

import numpy as np
import pytest

from rafostrack.posterior import summarise


def test_summarise_weighted_mean_and_spread():
    lat = np.array([-58.0, -58.0, -58.0 + 10 / 111.4])
    lon = np.array([-90.0, -90.0, -90.0])
    s = summarise(lat, lon, np.array([0.25, 0.25, 0.5]))
    assert s.lat == pytest.approx(-58.0 + 5 / 111.4, abs=1e-3)
    assert s.sd_km == pytest.approx(5.0, rel=0.01)  # half the mass 10 km north: sd 5 km
