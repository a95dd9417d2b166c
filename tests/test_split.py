"""Windows where the two-filter smoother's filters hold the float apart (`smoothing.split`):
flagged, both positions kept, the sd covering both, whatever the filter's seed."""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest
from scipy.stats import chi2

from rafostrack.config import load_config, with_overrides
from rafostrack.domain import ArrivalRecord, Cloud, Particles
from rafostrack.errors import WarningKind, kind_of
from rafostrack.model.geodesy import displace, local_offsets_km
from rafostrack.problem import FloatProblem
from rafostrack.run.method import track_record
from rafostrack.sim.evaluate import confidently_wrong, position_errors_km
from rafostrack.sim.scenarios import synthetic_scenario
from rafostrack.sim.simulate import simulate_arrivals
from rafostrack.smoothing.split import SPLIT_D2, SPLIT_MIN_KM, split_of

T0 = np.datetime64("2010-01-01T00:00", "ns")


def _cloud(rng, east_km: float, sd_km: float, n: int = 400) -> Cloud:
    lat, lon = displace(np.full(n, -58.0), np.full(n, -90.0), rng.normal(east_km, sd_km, n), rng.normal(0.0, sd_km, n))
    return Cloud(T0, Particles(lat, lon), np.full(n, 1.0 / n))


def test_the_threshold_is_the_chi2_quantile_of_two_degrees_of_freedom():
    assert SPLIT_D2 == pytest.approx(chi2.ppf(0.999, 2), abs=0.01)


@pytest.mark.parametrize(
    ("apart_km", "sd_km", "split"), [(60, 5, True), (60, 40, False), (10, 1, False), (25, 2, True)]
)
def test_clouds_apart_beyond_their_spread_and_the_minimum_are_a_split(apart_km, sd_km, split):
    """d^2 of the means against the summed covariances, checked by hand: a split when beyond
    `SPLIT_D2` and `SPLIT_MIN_KM`; its spread is the outer product of half the gap."""
    rng = np.random.default_rng(1)
    forward, backward = _cloud(rng, 0.0, sd_km), _cloud(rng, apart_km, sd_km)
    found = split_of(forward, backward)
    xy = [np.column_stack(local_offsets_km(c.lat, c.lon, -58.0, -90.0)) for c in (forward, backward)]
    gap = xy[1].mean(axis=0) - xy[0].mean(axis=0)
    d2 = gap @ np.linalg.solve(np.cov(xy[0].T, bias=True) + np.cov(xy[1].T, bias=True), gap)
    assert (found is not None) == split == (d2 > SPLIT_D2 and np.hypot(*gap) > SPLIT_MIN_KM)
    if found is not None:
        assert found.distance_km == pytest.approx(np.hypot(*gap), rel=5e-3)
        assert np.trace(found.spread_km2) == pytest.approx(found.distance_km**2 / 4, rel=1e-9)


DAYS, FIRST, LAST = 60, 18, 42  # only two sources heard from day FIRST to LAST


@pytest.fixture(scope="module")
def mirror_float():
    """A float that drifts towards the line between two opposite sources, touches it at
    day 30 and turns back, while only those two are heard: its mirror image, across the
    line, explains the arrivals as well, and a filter that keeps its momentum crosses over
    (the forward filter after day 30, the backward one before it)."""
    beacons, (info,) = synthetic_scenario(n_beacons=6, days=DAYS, rng=4)
    pair = [0, 3]
    e, n = (float(v) for v in local_offsets_km(beacons.lat[3], beacons.lon[3], beacons.lat[0], beacons.lon[0]))
    along = np.array([e, n]) / np.hypot(e, n)
    across = np.array([-along[1], along[0]])
    mid_lat, mid_lon = displace(beacons.lat[0], beacons.lon[0], e / 2, n / 2)
    times = np.datetime64(info.launch_time, "ns") + np.arange(DAYS + 1) * np.timedelta64(1, "D")
    off_km = -np.abs(np.arange(DAYS + 1) - 30.0) * 4.0
    lat, lon = displace(np.full(DAYS + 1, float(mid_lat)), np.full(DAYS + 1, float(mid_lon)),
                        off_km * across[0] + 40 * along[0], off_km * across[1] + 40 * along[1])  # fmt: skip
    truth = pd.DataFrame({"time": times, "lat": lat, "lon": lon})
    info = dataclasses.replace(info, launch_lat=float(lat[0]), launch_lon=float(lon[0]), end_time=times[-1],
                               end_lat=float(lat[-1]), end_lon=float(lon[-1]), max_signals=6)  # fmt: skip
    model = dataclasses.replace(load_config().model, toa_sigma_s=1.5, clutter_rate=0.5)
    rng = np.random.default_rng(0)
    full, _ = simulate_arrivals(beacons, info, model, truth, rng)
    fields = ("beacon_id", "lat", "lon", "offset_s", "drift_s_per_day", "start", "end")
    two = dataclasses.replace(beacons, **{f: getattr(beacons, f)[pair] for f in fields})
    two_heard, _ = simulate_arrivals(two, info, model, truth, rng)
    windows = [two_heard.windows[k] if FIRST <= k < LAST else w for k, w in enumerate(full.windows)]
    return beacons, info, ArrivalRecord(full.float_id, full.path, tuple(windows)), truth


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_mirror_stretch_is_flagged_under_every_seed(mirror_float, seed):
    """Under each seed the filters part where only the two sources are heard: windows of
    that stretch are ambiguous, a warning names them, and no window is confidently wrong."""
    beacons, info, record, truth = mirror_float
    config = with_overrides(load_config(), filter={"seed": seed, "particles": 500})
    out = track_record(FloatProblem(beacons, info, config), record)
    status = out.track["status"].astype(str).to_numpy()
    (warning,) = [w for w in out.warnings if kind_of(w) == WarningKind.SPLIT_TRACK]
    flagged = np.flatnonzero(status == "ambiguous")
    assert np.any((flagged >= FIRST) & (flagged < LAST))
    assert str(np.datetime64(record.windows[flagged[(flagged >= FIRST) & (flagged < LAST)][0]].time, "D")) in warning
    error = position_errors_km(out.track, truth)
    assert not confidently_wrong(error, out.track["sd_km"].to_numpy()).any()
    modes = out.final.estimate.modes
    modes = modes[modes["time"].isin(out.track["time"].to_numpy()[flagged])]
    assert set(modes.groupby("time")["mode"].count()) == {2}
