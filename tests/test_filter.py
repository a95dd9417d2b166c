"""The forward particle filter (`rafostrack.filtering.filter`): steps, guards, memory."""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd

from rafostrack.config import load_config, with_overrides
from rafostrack.likelihoods import RankedArrivals
from rafostrack.motion import ClockWalk
from rafostrack.problem import FloatProblem
from rafostrack.run.method import track_record
from rafostrack.run.one_pass import Tracker
from rafostrack.sim.evaluate import position_errors_km
from rafostrack.sim.scenarios import synthetic_scenario
from rafostrack.sim.simulate import simulate_mission
from rafostrack.summaries.posterior import summarise


def test_end_fix_is_the_last_step_and_pulls_the_cloud(sim_mission):
    sim = sim_mission.floats[0]
    config = with_overrides(load_config(), filter={"particles": 300})
    run = Tracker.from_problem(FloatProblem(sim_mission.beacons, sim.info, config)).run_filter(sim.record)
    assert run.steps[-1].window is None and run.steps[-1].cloud.time == sim.info.end_time
    assert sum(s.window is not None for s in run.steps) == len(sim.record.windows)
    last = summarise(run.steps[-1].cloud.lat, run.steps[-1].cloud.lon, run.steps[-1].cloud.weights)
    before = summarise(run.steps[-2].cloud.lat, run.steps[-2].cloud.lon, run.steps[-2].cloud.weights)
    assert last.sd_km < before.sd_km  # a 1 km fix tightens a ~3 km cloud


def test_non_finite_likelihoods_are_dropped_or_skipped_with_a_warning(sim_mission, monkeypatch):
    """If the likelihood of a step is NaN for some particles, they get zero weight; if for all,
    the step is skipped. Either way the run finishes with finite output and a warning."""
    sim = sim_mission.floats[0]
    config = with_overrides(
        load_config(),
        filter={"particles": 200},
        smoother={"enabled": False},
        recovery={"enabled": False},  # its searches would call the patched likelihood too
        calibrate={"enabled": False},  # one pass: the patched calls are counted in it
    )
    original = RankedArrivals.evaluate
    calls = {"n": 0}

    def broken(self, particles, window, **kw):
        evidence = original(self, particles, window, **kw)
        calls["n"] += 1
        loglik = evidence.loglik
        if calls["n"] == 5:
            loglik = np.full_like(loglik, np.nan)
        elif calls["n"] == 9:
            loglik = loglik.copy()
            loglik[:50] = np.nan
        return type(evidence)(loglik, evidence.beacon_index, evidence.p_match, evidence.warnings)

    monkeypatch.setattr(RankedArrivals, "evaluate", broken)
    out = track_record(FloatProblem(sim_mission.beacons, sim.info, config), sim.record)
    assert len(out.warnings) == 2
    assert "skipped" in out.warnings[0] and "dropped" in out.warnings[1]
    assert np.isnan(out.track["loglik"].iloc[4])
    assert np.all(np.isfinite(out.track[["lat", "lon", "sd_km"]].to_numpy()))


def test_filter_only_memory_does_not_grow_with_the_record():
    """Without smoothing no history is kept: the peak of traced memory while filtering 600
    windows with 1000 particles stays well below the 24 MB that the clouds alone would take
    (position, velocity and weight: 5 numbers per particle)."""
    import tracemalloc

    config = with_overrides(load_config(), smoother={"enabled": False}, calibrate={"enabled": False})
    beacons, floats = synthetic_scenario(days=600, rng=2)
    sim = simulate_mission(beacons, floats, config.model, np.random.default_rng(2)).floats[0]
    history_bytes = len(sim.record.windows) * config.filter.particles * 5 * 8
    tracemalloc.start()
    try:
        track_record(FloatProblem(beacons, sim.info, config), sim.record)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert history_bytes >= 24e6
    assert peak < 0.5 * history_bytes


def test_with_the_clock_in_the_state_a_wrong_end_clock_offset_does_not_move_the_track():
    """A float whose clock drifted 40 s in 60 days, tracked with floats.csv saying it never
    drifted (end offset = start offset): the filter that takes the table's clock as given
    moves the float to explain the growing common shift; with each particle's clock
    correction in the state (`ClockWalk`, as in the first pass) the track stays on the
    truth and the correction follows the true clock (the generator is the tracker's own
    simulator, with the clock it was told)."""
    beacons, (info,) = synthetic_scenario(days=60, rng=5)
    true_info = dataclasses.replace(info, clock_offset_start_s=0.0, clock_offset_end_s=40.0)
    model = dataclasses.replace(load_config().model, toa_sigma_s=1.0, clutter_rate=0.5)
    sim = simulate_mission(beacons, [true_info], model, np.random.default_rng(5)).floats[0]
    told = dataclasses.replace(true_info, clock_offset_end_s=0.0)
    config = with_overrides(load_config(), filter={"particles": 2000}, model={"toa_sigma_s": 1.0, "clutter_rate": 0.5})
    tracker = Tracker.from_problem(FloatProblem(beacons, told, config))  # 500 particles: 3-20 km by filter seed
    clocked = dataclasses.replace(tracker, motion=ClockWalk(tracker.motion, 0.5, 0.5))
    errors, clock_errors = {}, []
    for name, t in (("table", tracker), ("clocked", clocked)):
        run = t.run_filter(sim.record)
        windows = [s for s in run.steps if s.window is not None]
        means = [summarise(s.cloud.lat, s.cloud.lon, s.cloud.weights) for s in windows]
        estimate = pd.DataFrame({"time": [s.cloud.time for s in windows], "lat": [m.lat for m in means],
                                 "lon": [m.lon for m in means]})  # fmt: skip
        errors[name] = position_errors_km(estimate, sim.truth)
        if name == "clocked":
            for s in windows[-20:]:
                true_correction = float(true_info.clock_offset_s(s.cloud.time) - told.clock_offset_s(s.cloud.time))
                clock_errors.append(float(s.cloud.weights @ s.cloud.particles.clock_s) - true_correction)
    late = slice(-20, None)  # the last 20 windows: the true clock 27-40 s from the table's
    assert np.sqrt(np.mean(errors["table"][late] ** 2)) > 20.0  # 58 km here
    assert np.sqrt(np.mean(errors["clocked"][late] ** 2)) < 5.0  # 2.5-2.9 km over filter seeds 0-5
    assert np.sqrt(np.mean(np.square(clock_errors))) < 2.5  # 1.6 s here
