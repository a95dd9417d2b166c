"""The stress scenario (`rafostrack.sim.stress`): reproducible, each knob doing what it says, and
the events it reports matching the record it writes."""

from __future__ import annotations

import numpy as np
import pytest

from rafostrack.sim.stress import DAY_NS, StressConfig, simulate_stress, with_knobs
from rafostrack.sim.stress_float import _clutter_toas

QUIET = StressConfig(
    days=60, gaps=False, fading=False, bad_propagation=False, multipath=False, outage=False, burst_prob=0.0
)


def _float(cfg: StressConfig, seed: int = 3):
    return simulate_stress("dimes", 1, np.random.default_rng(seed), cfg).floats[0]


def test_same_seed_same_float_different_seed_different():
    a, b, c = _float(StressConfig(days=60)), _float(StressConfig(days=60)), _float(StressConfig(days=60), seed=4)
    assert a.events == b.events and a.truth.equals(b.truth)
    assert all(np.array_equal(x.toa_s, y.toa_s) for x, y in zip(a.record.windows, b.record.windows, strict=True))
    assert not a.truth["lat"].equals(c.truth["lat"])


def test_a_recording_gap_has_no_windows_and_is_reported():
    sim = _float(with_knobs(QUIET, {"gaps": True, "missing_day_prob": 0.0}))
    start = sim.truth["time"].iloc[0]
    day = np.array([(w.time - start) // DAY_NS for w in sim.record.windows])
    gaps = sim.events["gaps_days"]
    assert len(gaps) >= 1
    for first, last in gaps:
        assert not np.any((day >= first) & (day <= last))  # days first..last have no window
    in_gaps = set().union(*(range(first, last + 1) for first, last in gaps))  # gaps may overlap
    assert len(day) == QUIET.days - len(in_gaps)  # and no other day is missing


def test_stored_signals_are_the_earliest_and_at_most_max_signals():
    sim = _float(with_knobs(QUIET, {"clutter_rate": 3.0}))
    assert all(w.n_signals <= QUIET.max_signals for w in sim.record.windows)
    assert all(np.all(np.diff(w.toa_s) >= 0) for w in sim.record.windows)
    assert max(w.n_signals for w in sim.record.windows) == QUIET.max_signals


def test_clutter_rate_sets_the_share_of_unlabelled_arrivals():
    def clutter_share(rate: float) -> float:
        sim = _float(with_knobs(QUIET, {"clutter_rate": rate, "max_signals": 12}))
        labels = [b for w in sim.record.windows for b in w.beacon_id]
        return float(np.mean([b is None for b in labels]))

    assert clutter_share(0.0) == 0.0
    assert 0.05 < clutter_share(1.0) < clutter_share(3.0) < 0.6


def test_multipath_off_means_every_labelled_arrival_is_direct_within_the_noise():
    """Without multipath, each beacon is stored at most once per window (no echoes)."""
    sim = _float(QUIET)
    for w in sim.record.windows:
        heard = [b for b in w.beacon_id if b is not None]
        assert len(heard) == len(set(heard))


def test_too_short_a_mission_for_its_gaps_is_a_clear_error():
    with pytest.raises(ValueError, match="days must be at least"):
        StressConfig(days=20)
    StressConfig(days=20, gaps=False)
    with pytest.raises(ValueError, match="unknown stress knob"):
        with_knobs(QUIET, {"gap": True})


def test_tapered_clutter_has_the_stated_density():
    """`clutter_taper` a: density proportional to 1 - a x on the window (x in [0, 1]); mean
    x (1/2 - a/3) / (1 - a/2), share past 0.9 (0.1 - a 0.095) / (1 - a/2). a = 0 draws what
    the uniform clutter always drew."""
    for a in (0.5, 1.0):
        x = _clutter_toas(200_000, 4200.0, a, np.random.default_rng(1)) / 4200.0
        assert 0.0 <= x.min() and x.max() <= 1.0
        assert x.mean() == pytest.approx((0.5 - a / 3) / (1 - a / 2), abs=3e-3)
        assert (x > 0.9).mean() == pytest.approx((0.1 - a * 0.095) / (1 - a / 2), abs=2e-3)
    uniform = np.random.default_rng(2).uniform(0.0, 4200.0, 50)
    assert np.array_equal(_clutter_toas(50, 4200.0, 0.0, np.random.default_rng(2)), uniform)
