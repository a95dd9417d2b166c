"""The particle filter tracks simulated missions: labels and positions against truth."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from rafostrack.config import load_config, with_overrides
from rafostrack.evaluate import association_accuracy, position_errors_km
from rafostrack.filter import ParticleFilter, fix_loglik, float_rng
from rafostrack.posterior import summarise
from rafostrack.simulate import simulate_mission, synthetic_scenario
from rafostrack.tracker import track_record


@pytest.fixture(scope="module")
def mission():
    config = load_config()
    beacons, floats = synthetic_scenario(days=60, rng=7)
    return simulate_mission(beacons, floats, config.model, np.random.default_rng(7))


def _run(mission, method, particles=500, seed=0):
    """The filtered estimate (smoother off): this module tests the forward filter."""
    config = with_overrides(
        load_config(),
        filter={"method": method, "particles": particles, "seed": seed},
        smoother={"enabled": False},
    )
    sim = mission.floats[0]
    return sim, track_record(mission.beacons, sim.info, config, sim.record)


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


def test_end_fix_is_the_last_step_and_pulls_the_cloud(mission):
    sim = mission.floats[0]
    config = with_overrides(load_config(), filter={"particles": 300})
    run = ParticleFilter(mission.beacons, sim.info, config).run(sim.record, float_rng(0, sim.info.float_id))
    assert run.steps[-1].window is None and run.steps[-1].cloud.time == sim.info.end_time
    assert len(run.window_steps) == len(sim.record.windows)
    last = summarise(run.steps[-1].cloud.lat, run.steps[-1].cloud.lon, run.steps[-1].cloud.weights)
    before = summarise(run.steps[-2].cloud.lat, run.steps[-2].cloud.lon, run.steps[-2].cloud.weights)
    assert last.sd_km < before.sd_km  # a 1 km fix tightens a ~3 km cloud


def test_fix_loglik_is_a_normalised_2d_gaussian():
    lat, lon = np.array([-58.0, -58.0]), np.array([-90.0, -90.0 + 3.0 / 59.0])
    ll = fix_loglik(lat, lon, -58.0, -90.0, 2.0)
    assert ll[0] == pytest.approx(-np.log(2 * np.pi * 4.0))
    assert ll[0] - ll[1] == pytest.approx(0.5 * (3.0 / 2.0) ** 2, rel=0.02)


def test_summarise_weighted_mean_and_spread():
    lat = np.array([-58.0, -58.0, -58.0 + 10 / 111.4])
    lon = np.array([-90.0, -90.0, -90.0])
    s = summarise(lat, lon, np.array([0.25, 0.25, 0.5]))
    assert s.lat == pytest.approx(-58.0 + 5 / 111.4, abs=1e-3)
    assert s.sd_km == pytest.approx(5.0, rel=0.01)  # half the mass 10 km north: sd 5 km


def test_a_wild_hand_label_is_widened_not_collapsed_onto(mission):
    """A labelled TOA 500 s off every prediction: no particle explains it. The filter
    widens that TOA's sd, records a warning, and the track stays on course."""
    sim = mission.floats[0]
    windows = list(sim.record.windows)
    k = next(i for i, w in enumerate(windows) if i > 20 and w.beacon_id and w.beacon_id[0] is not None)
    bad = windows[k]
    windows[k] = dataclasses.replace(bad, toa_s=np.concatenate([[bad.toa_s[0] + 500.0], bad.toa_s[1:]]))
    record = dataclasses.replace(sim.record, windows=tuple(windows))
    config = with_overrides(load_config(), filter={"method": "labeled", "particles": 500}, smoother={"enabled": False})
    out = track_record(mission.beacons, sim.info, config, record)
    assert len(out.warnings) == 1 and "sd was widened" in out.warnings[0]
    assert np.all(np.isfinite(out.track[["lat", "lon", "sd_km"]].to_numpy()))
    assert np.sqrt(np.mean(position_errors_km(out.track, sim.truth) ** 2)) < 6.0


def test_an_end_fix_far_from_every_particle_is_widened(mission):
    sim = mission.floats[0]
    info = dataclasses.replace(sim.info, end_lat=sim.info.end_lat + 2.0)  # ~220 km off
    config = with_overrides(load_config(), filter={"particles": 300})
    out = track_record(mission.beacons, info, config, sim.record)
    assert any("end fix" in w and "widened" in w for w in out.warnings)
    assert np.all(np.isfinite(out.track[["lat", "lon", "sd_km", "smaj_km"]].to_numpy()))


def test_non_finite_likelihoods_are_dropped_or_skipped_with_a_warning(mission, monkeypatch):
    """If the likelihood of a step is NaN for some particles, they get zero weight; if for all,
    the step is skipped. Either way the run finishes with finite output and a warning."""
    sim = mission.floats[0]
    config = with_overrides(load_config(), filter={"particles": 200}, smoother={"enabled": False})
    original = ParticleFilter.window_loglik
    calls = {"n": 0}

    def broken(self, lat, lon, window, **kw):
        loglik, p_match, wb = original(self, lat, lon, window, **kw)
        calls["n"] += 1
        if calls["n"] == 5:
            loglik = np.full_like(loglik, np.nan)
        elif calls["n"] == 9:
            loglik = loglik.copy()
            loglik[:50] = np.nan
        return loglik, p_match, wb

    monkeypatch.setattr(ParticleFilter, "window_loglik", broken)
    out = track_record(mission.beacons, sim.info, config, sim.record)
    assert len(out.warnings) == 2
    assert "skipped" in out.warnings[0] and "dropped" in out.warnings[1]
    assert np.isnan(out.track["loglik"].iloc[4])
    assert np.all(np.isfinite(out.track[["lat", "lon", "sd_km"]].to_numpy()))


def test_filter_only_memory_does_not_grow_with_the_record():
    """Without smoothing no history is kept: the peak of traced memory while tracking 600
    windows with 1000 particles stays well below the 14 MB that the clouds alone would take."""
    import tracemalloc

    config = with_overrides(load_config(), smoother={"enabled": False})
    beacons, floats = synthetic_scenario(days=600, rng=2)
    sim = simulate_mission(beacons, floats, config.model, np.random.default_rng(2)).floats[0]
    history_bytes = len(sim.record.windows) * config.filter.particles * 3 * 8
    tracemalloc.start()
    try:
        track_record(beacons, sim.info, config, sim.record)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert history_bytes > 14e6
    assert peak < 0.5 * history_bytes
