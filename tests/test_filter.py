"""The particle filter tracks simulated missions: labels and positions against truth."""

from __future__ import annotations

import numpy as np
import pytest

from rafostrack.config import load_config, with_overrides
from rafostrack.evaluate import association_accuracy, position_errors_km
from rafostrack.filter import ParticleFilter, float_rng, summarise
from rafostrack.simulate import simulate_mission, synthetic_scenario


@pytest.fixture(scope="module")
def mission():
    config = load_config()
    beacons, floats = synthetic_scenario(days=60, rng=7)
    return simulate_mission(beacons, floats, config.model, np.random.default_rng(7))


def _run(mission, method, particles=500, seed=0):
    config = with_overrides(load_config(), filter={"method": method, "particles": particles, "seed": seed})
    sim = mission.floats[0]
    out = ParticleFilter(mission.beacons, sim.info, config).run(sim.record, float_rng(seed, sim.info.float_id))
    return sim, out


@pytest.mark.parametrize("method", ["exact", "bp", "unranked"])
def test_tracks_simulated_float_within_margins(mission, method):
    """Clutter 1 per window, sigma 2 s (~3 km of range): >= 95% of TOAs labelled right and
    RMSE under 6 km, where a tracker that lost the float is off by tens of km."""
    sim, out = _run(mission, method)
    assert association_accuracy(out.labels, sim.record) >= 0.95
    err = position_errors_km(out.track, sim.truth)
    assert np.sqrt(np.mean(err**2)) < 6.0
    assert np.all(np.isfinite(out.track[["lat", "lon", "sd_km", "ess", "loglik"]].to_numpy()))


def test_labeled_method_reproduces_its_labels(mission):
    sim, out = _run(mission, "labeled")
    assert association_accuracy(out.labels, sim.record) == 1.0
    assert np.allclose(out.labels["prob"], 1.0)


def test_output_shapes_and_label_probabilities(mission):
    sim, out = _run(mission, "exact")
    assert len(out.track) == len(sim.record.windows)
    assert len(out.labels) == sum(w.n_signals for w in sim.record.windows)
    assert out.labels["rank"].min() == 1
    assert np.all((out.labels["prob"] >= 0.5 - 1e-12) | out.labels["beacon_id"].isna())
    assert np.all((0 <= out.labels["p_clutter"]) & (out.labels["p_clutter"] <= 1))
    # A label's probability is at least that of clutter or of its own beacon.
    clutter_rows = out.labels["beacon_id"].isna()
    assert np.allclose(out.labels.loc[clutter_rows, "prob"], out.labels.loc[clutter_rows, "p_clutter"])


def test_same_seed_same_result_different_seed_different(mission):
    _, a = _run(mission, "exact", particles=200, seed=3)
    _, b = _run(mission, "exact", particles=200, seed=3)
    _, c = _run(mission, "exact", particles=200, seed=4)
    assert a.track.equals(b.track) and a.labels.equals(b.labels)
    assert not a.track["lat"].equals(c.track["lat"])


def test_posterior_sd_is_calibrated_on_average(mission):
    """The reported spread tracks the actual error: the mean squared error is within a
    factor of three of the mean reported variance (a filter that collapsed would be far off)."""
    sim, out = _run(mission, "exact", particles=1000)
    err = position_errors_km(out.track, sim.truth)
    ratio = np.mean(err**2) / np.mean(out.track["sd_km"] ** 2)
    assert 1 / 3 < ratio < 3


def test_summarise_weighted_mean_and_spread():
    lat = np.array([-58.0, -58.0, -58.0 + 10 / 111.4])
    lon = np.array([-90.0, -90.0, -90.0])
    s = summarise(lat, lon, np.array([0.25, 0.25, 0.5]))
    assert s.lat == pytest.approx(-58.0 + 5 / 111.4, abs=1e-3)
    assert s.sd_km == pytest.approx(5.0, rel=0.01)  # half the mass 10 km north: sd 5 km
