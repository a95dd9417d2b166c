"""Likelihood components (`rafostrack.likelihoods`): position fixes, labelled arrivals, and
the ranked component against the model's factors and the exact engine."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from rafostrack.calibrate.release import FIX_KEPT_NOTE
from rafostrack.config import load_config, with_overrides
from rafostrack.domain import Particles
from rafostrack.engines import exact
from rafostrack.likelihoods import RankedArrivals, arrivals_from_config, fix_loglik
from rafostrack.model import measurement as m
from rafostrack.problem import FloatProblem
from rafostrack.run.method import track_record
from rafostrack.sim.evaluate import position_errors_km


def test_fix_loglik_is_a_normalised_2d_gaussian():
    lat, lon = np.array([-58.0, -58.0]), np.array([-90.0, -90.0 + 3.0 / 59.0])
    ll = fix_loglik(lat, lon, -58.0, -90.0, 2.0)
    assert ll[0] == pytest.approx(-np.log(2 * np.pi * 4.0))
    assert ll[0] - ll[1] == pytest.approx(0.5 * (3.0 / 2.0) ** 2, rel=0.02)


@pytest.mark.parametrize("ranked", [True, False])
def test_ranked_component_is_the_model_factors_summed_by_the_engine(sim_mission, ranked):
    """The component adds nothing of its own: log p = K log Lambda - Lambda h + log Z, with Z
    from the exact engine on `model.measurement.association_factors`."""
    sim = sim_mission.floats[0]
    model = load_config().model
    window = next(w for w in sim.record.windows if w.n_signals >= 3)
    rng = np.random.default_rng(1)
    lat = sim.truth["lat"].iloc[5] + rng.normal(0, 0.05, 50)
    lon = sim.truth["lon"].iloc[5] + rng.normal(0, 0.05, 50)
    component = RankedArrivals(sim_mission.beacons, sim.info, model, exact.associate, ranked=ranked)
    evidence = component.evaluate(Particles(lat, lon), window)
    wb = m.window_beacons(sim_mission.beacons, sim.info, window.time)
    ranges = m.beacon_ranges_m(lat, lon, wb)
    f = m.association_factors(
        m.predicted_toa_s(ranges, wb, model),
        m.detection_prob(ranges, wb, model),
        window.toa_s,
        max_signals=sim.info.max_signals,
        window_s=sim.info.window_s,
        model=model,
        ranked=ranked,
    )
    assert np.allclose(
        evidence.loglik,
        f.log_base + exact.associate(f.log_match, f.log_unheard, log_echo=f.log_echo).log_z,
        rtol=0,
        atol=1e-12,
    )
    assert evidence.p_match.shape == (50, len(wb.index), window.n_signals)


@pytest.mark.parametrize("likelihood", ["ranked", "labeled"])
def test_a_likelihood_evaluated_window_after_window_gives_what_a_fresh_one_does(sim_mission, likelihood):
    """What a likelihood keeps of a window from one evaluation to the next (its beacons, its
    signals' terms, its labels) is that window's: windows evaluated in turn, again, and by a
    copy with another TOA sd give the bits that a likelihood made for each evaluation gives."""
    sim = sim_mission.floats[0]
    config = with_overrides(load_config(), filter={"likelihood": likelihood})
    windows = [w for w in sim.record.windows if w.n_signals >= 2][:3]
    rng = np.random.default_rng(2)
    particles = Particles(
        sim.truth["lat"].iloc[5] + rng.normal(0, 0.05, 40), sim.truth["lon"].iloc[5] + rng.normal(0, 0.05, 40)
    )

    def fresh():
        return arrivals_from_config(sim_mission.beacons, sim.info, config)

    kept = fresh()
    for window in [*windows, *reversed(windows)]:
        assert np.array_equal(kept.evaluate(particles, window).loglik, fresh().evaluate(particles, window).loglik)
    wide, wide_fresh = kept.with_toa_sigma(5.0), fresh().with_toa_sigma(5.0)
    for window in windows:
        assert np.array_equal(wide.evaluate(particles, window).loglik, wide_fresh.evaluate(particles, window).loglik)
    assert not np.array_equal(wide.evaluate(particles, windows[0]).loglik, kept.evaluate(particles, windows[0]).loglik)


def test_a_wild_hand_label_is_widened_not_collapsed_onto(sim_mission):
    """A labelled TOA 500 s off every prediction: no particle explains it. The filter
    widens that TOA's sd, records a warning, and the track stays on course."""
    sim = sim_mission.floats[0]
    windows = list(sim.record.windows)
    k = next(i for i, w in enumerate(windows) if i > 20 and w.beacon_id and w.beacon_id[0] is not None)
    bad = windows[k]
    windows[k] = dataclasses.replace(bad, toa_s=np.concatenate([[bad.toa_s[0] + 500.0], bad.toa_s[1:]]))
    record = dataclasses.replace(sim.record, windows=tuple(windows))
    config = with_overrides(
        load_config(),
        filter={"likelihood": "labeled", "particles": 500},
        smoother={"enabled": False},
        calibrate={"enabled": False},  # one pass with the configured model: one wild label, one warning
    )
    out = track_record(FloatProblem(sim_mission.beacons, sim.info, config), record)
    assert len(out.warnings) == 1 and "sd was widened" in out.warnings[0]
    assert np.all(np.isfinite(out.track[["lat", "lon", "sd_km"]].to_numpy()))
    assert np.sqrt(np.mean(position_errors_km(out.track, sim.truth) ** 2)) < 6.0


def test_an_end_fix_far_from_every_particle_is_widened(sim_mission):
    """Without the metadata checks, the filter widens an end fix that no particle is near;
    with them (the default), calibration names the fix with the distance the arrivals put it
    at, and keeps it (a GPS fix is data, `release.FIX_KEPT_BEYOND_KM`): the track follows the
    arrivals but for its last days, and its last window is ambiguous."""
    sim = sim_mission.floats[0]
    info = dataclasses.replace(sim.info, end_lat=sim.info.end_lat + 2.0)  # ~220 km off
    unchecked = with_overrides(load_config(), filter={"particles": 300}, checks={"enabled": False})
    out = track_record(FloatProblem(sim_mission.beacons, info, unchecked), sim.record)
    assert any("end fix" in w and "widened" in w for w in out.warnings)
    assert np.all(np.isfinite(out.track[["lat", "lon", "sd_km", "smaj_km"]].to_numpy()))
    checked = with_overrides(unchecked, checks={"enabled": True})
    out = track_record(FloatProblem(sim_mission.beacons, info, checked), sim.record)
    assert any("field 'end_fix'" in w and "the arrivals support" in w and FIX_KEPT_NOTE in w for w in out.warnings)
    error = position_errors_km(out.track, sim.truth)
    assert np.sqrt(np.mean(error[:-3] ** 2)) < 10.0
    assert out.track["status"].iloc[-1] == "ambiguous"
