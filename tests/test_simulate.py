"""The mission simulator: round trip through the readers, determinism, generator statistics."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from rafostrack.config import ModelConfig, load_config
from rafostrack.domain import BeaconTable, FloatInfo
from rafostrack.errors import Warnings
from rafostrack.io.csv_mission import read_arrivals, read_beacons, read_floats
from rafostrack.model.geodesy import local_offsets_km, range_m
from rafostrack.model.measurement import predicted_arrivals
from rafostrack.sim.mission_writer import write_mission
from rafostrack.sim.scenarios import dimes_scenario, synthetic_scenario
from rafostrack.sim.simulate import SimulatedMission, simulate_drift, simulate_mission, summarize

# The simulator's checks below are of one arrival per detected source: echoes off (they have
# their own test).
DEFAULT_MODEL = dataclasses.replace(load_config().model, echo_fraction=0.0)
NAT = np.datetime64("NaT", "ns")


def model_with(**changes) -> ModelConfig:
    return dataclasses.replace(DEFAULT_MODEL, **changes)


def roomy(floats: list[FloatInfo], max_signals: int = 50) -> list[FloatInfo]:
    """Floats that store every signal they receive."""
    return [dataclasses.replace(f, max_signals=max_signals) for f in floats]


def shifted(beacons: BeaconTable, by_s: float = 100.0) -> BeaconTable:
    """Offsets moved into the window so no true arrival can fall before it opens."""
    return dataclasses.replace(beacons, offset_s=beacons.offset_s + by_s)


def small_mission(seed: int) -> SimulatedMission:
    beacons, floats = synthetic_scenario(n_beacons=6, days=25, rng=3, n_floats=2)
    # A third float with no end fix (simulated for `days`), and few signals so that some
    # windows store nothing.
    no_end = dataclasses.replace(
        floats[0], float_id="noend", end_time=NAT, end_lat=np.nan, end_lon=np.nan, clock_offset_end_s=0.5
    )
    model = model_with(p_detect=0.35, clutter_rate=0.3, multipath_fraction=0.2)
    return simulate_mission(beacons, [*floats, no_end], model, np.random.default_rng(seed), days=25)


def read_back(outdir: Path, model: ModelConfig):
    beacons = read_beacons(outdir / "beacons.csv")
    infos = read_floats(outdir / "floats.csv", model)
    warnings = Warnings()
    records = {fid: read_arrivals(outdir / f"{fid}.csv", info, beacons, warnings) for fid, info in infos.items()}
    return beacons, infos, records, warnings


PROVENANCE = {"source", "source_file", "source_line"}  # where a table was read: not simulated


def assert_info_equal(a: FloatInfo, b: FloatInfo) -> None:
    for f in dataclasses.fields(FloatInfo):
        if f.name in PROVENANCE:
            continue
        x, y = getattr(a, f.name), getattr(b, f.name)
        if isinstance(x, float) and np.isnan(x):
            assert np.isnan(y), f.name
        elif isinstance(x, np.datetime64):
            assert (np.isnat(x) and np.isnat(y)) or x == y, f.name
        else:
            assert x == y, f.name


# --------------------------------------------------------------------------------------
# Files


def test_round_trip_gives_same_windows_labels_and_config(tmp_path):
    mission = small_mission(seed=11)
    write_mission(mission, tmp_path, config_overrides={"filter": {"particles": 123}})
    beacons, infos, records, warnings = read_back(tmp_path, mission.model)
    assert not warnings.messages

    for f in dataclasses.fields(BeaconTable):
        a, b = getattr(mission.beacons, f.name), getattr(beacons, f.name)
        if f.name in PROVENANCE:
            assert a is None and b is not None, f.name
        elif a is None:  # per-beacon calibration values: none simulated, none read
            assert b is None, f.name
        elif a.dtype.kind == "M":
            assert np.array_equal(np.isnat(a), np.isnat(b)) and np.all((a == b) | np.isnat(a))
        else:
            assert np.array_equal(a, b), f.name

    assert list(infos) == [sf.info.float_id for sf in mission.floats]
    n_empty = 0
    for sf in mission.floats:
        assert_info_equal(sf.info, infos[sf.info.float_id])
        got = records[sf.info.float_id].windows
        assert len(got) == len(sf.record.windows) > 0
        for w_sim, w_read in zip(sf.record.windows, got, strict=True):
            assert w_sim.time == w_read.time
            assert np.array_equal(w_sim.toa_s, w_read.toa_s)  # bit-exact: TOAs are quantised
            assert w_sim.beacon_id == w_read.beacon_id
            n_empty += w_sim.n_signals == 0
        truth = pd.read_csv(tmp_path / "truth" / f"{sf.info.float_id}.csv")
        assert list(truth.columns) == ["time", "lat", "lon"]
        times = pd.to_datetime(truth["time"], utc=True).dt.tz_convert(None).to_numpy("datetime64[ns]")
        assert np.array_equal(times, sf.truth["time"].to_numpy("datetime64[ns]"))
        assert range_m(truth["lat"], truth["lon"], sf.truth["lat"], sf.truth["lon"]).max() < 0.2
    assert n_empty > 0  # the "listened, stored nothing" row was exercised

    config = load_config([tmp_path / "rafostrack.toml"])
    assert config.model == mission.model
    assert config.filter.particles == 123


def test_bad_config_override_is_rejected_before_writing(tmp_path):
    mission = small_mission(seed=1)
    with pytest.raises(Exception, match="particels"):
        write_mission(mission, tmp_path, config_overrides={"filter": {"particels": 10}})
    assert not any(tmp_path.iterdir())


def file_bytes(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def test_same_seed_same_bytes_different_seed_different(tmp_path):
    for name, seed in (("a", 5), ("b", 5), ("c", 6)):
        write_mission(small_mission(seed), tmp_path / name)
    a, b, c = (file_bytes(tmp_path / n) for n in "abc")
    assert set(a) == {
        "beacons.csv", "floats.csv", "rafostrack.toml", "sim1.csv", "sim2.csv", "noend.csv",
        "truth/sim1.csv", "truth/sim2.csv", "truth/noend.csv",
    }  # fmt: skip
    assert a == b
    assert a["beacons.csv"] == c["beacons.csv"]  # the scenario does not depend on the seed
    for name in ("sim1.csv", "sim2.csv", "noend.csv", "truth/sim1.csv", "truth/noend.csv"):
        assert a[name] != c[name], name


# --------------------------------------------------------------------------------------
# Generator statistics


def test_detected_fraction_matches_p_detect():
    beacons, floats = synthetic_scenario(n_beacons=16, days=300, rng=2)
    model = model_with(p_detect=0.7, detection_range_km=0.0, clutter_rate=0.05)
    mission = simulate_mission(shifted(beacons), roomy(floats), model, np.random.default_rng(7))
    sf = mission.floats[0]
    heard = sum(lab is not None for w in sf.record.windows for lab in w.beacon_id)
    trials = len(sf.record.windows) * len(beacons)  # all beacons always active, all in window
    assert trials == 4800
    assert abs(heard / trials - 0.7) < 0.03  # sd 0.0066
    # each beacon is heard at most once per window
    for w in sf.record.windows:
        labels = [lab for lab in w.beacon_id if lab is not None]
        assert len(labels) == len(set(labels))


def test_clutter_is_poisson_and_uniform():
    beacons, floats = synthetic_scenario(n_beacons=4, days=1000, rng=4)
    model = model_with(p_detect=0.5, clutter_rate=2.5)
    mission = simulate_mission(beacons, roomy(floats), model, np.random.default_rng(8))
    windows = mission.floats[0].record.windows
    counts = np.array([sum(lab is None for lab in w.beacon_id) for w in windows])
    assert len(counts) == 1000
    assert abs(counts.mean() - 2.5) < 0.2  # sd 0.05
    assert 0.8 < counts.var() / counts.mean() < 1.2  # Poisson: variance = mean
    times = np.concatenate([w.toa_s[[lab is None for lab in w.beacon_id]] for w in windows])
    assert times.min() >= 0.0 and times.max() <= 4200.0
    assert abs(times.mean() - 2100.0) < 100.0  # uniform on [0, 4200]: sd of the mean ~24 s
    assert abs(np.mean(times < 1050.0) - 0.25) < 0.03


def test_storage_keeps_the_earliest_max_signals():
    beacons, floats = synthetic_scenario(n_beacons=8, days=400, rng=5)
    model = model_with(p_detect=0.4, clutter_rate=1.5, multipath_fraction=0.3)
    mission = simulate_mission(beacons, floats, model, np.random.default_rng(9))
    sf = mission.floats[0]
    r = sf.info.max_signals
    by_window = dict(tuple(sf.arrivals.groupby("time")))
    n_full = n_short = 0
    for w in sf.record.windows:
        assert w.n_signals <= r
        assert np.all(np.diff(w.toa_s) > 0)
        received = by_window.get(w.time, sf.arrivals.iloc[:0])
        assert np.all(np.diff(received["toa_s"].to_numpy()) > 0)
        assert w.n_signals == min(len(received), r)  # full exactly when >= r signals arrived
        assert np.array_equal(w.toa_s, received["toa_s"].to_numpy()[: w.n_signals])
        assert w.beacon_id == tuple(received["beacon_id"].iloc[: w.n_signals])
        assert received["stored"].sum() == w.n_signals
        n_full += len(received) >= r
        n_short += len(received) < r
    assert n_full > 50 and n_short > 10  # both cases exercised


def test_true_toas_follow_the_model_including_clock_offset():
    beacons, floats = synthetic_scenario(n_beacons=8, days=200, rng=6)
    info = dataclasses.replace(floats[0], clock_offset_start_s=30.0, clock_offset_end_s=-30.0)
    drifting = dataclasses.replace(beacons, drift_s_per_day=np.linspace(-0.1, 0.1, len(beacons)))
    # Gaussian: mean 0, sd 2 (sd of the estimates ~0.07, ~0.05). With multipath half the
    # arrivals are delayed by Exp(mean 20 s): mean 10 s, sd sqrt(4 + 300) (mean's sd ~0.6).
    for eps, expected_mean, mean_tol, expected_sd, sd_tol in ((0.0, 0.0, 0.3, 2.0, 0.2), (0.5, 10.0, 2.0, 17.4, 5.0)):
        model = model_with(multipath_fraction=eps, multipath_delay_s=20.0, clutter_rate=0.1)
        sf = simulate_mission(drifting, [info], model, np.random.default_rng(10)).floats[0]
        times = np.array([w.time for w in sf.record.windows])
        truth = sf.truth.set_index("time").loc[times]
        mu = predicted_arrivals(times, truth["lat"].to_numpy(), truth["lon"].to_numpy(), drifting, info, model)
        col = drifting.index_of()
        resid = np.array(
            [
                toa - mu[k, col[lab]]
                for k, w in enumerate(sf.record.windows)
                for toa, lab in zip(w.toa_s, w.beacon_id, strict=True)
                if lab is not None
            ]
        )
        assert len(resid) > 500
        assert abs(resid.mean() - expected_mean) < mean_tol
        assert abs(resid.std() - expected_sd) < sd_tol


def test_detection_probability_falls_with_range():
    beacons, floats = synthetic_scenario(n_beacons=8, days=200, rng=6)
    near = simulate_mission(beacons, roomy(floats), model_with(detection_range_km=0.0), np.random.default_rng(1))
    far = simulate_mission(
        beacons, roomy(floats), model_with(detection_range_km=300.0, detection_falloff_km=20.0),
        np.random.default_rng(1),
    )  # fmt: skip
    heard = [sum(lab is not None for w in m.floats[0].record.windows for lab in w.beacon_id) for m in (near, far)]
    assert heard[1] < 0.2 * heard[0]  # the ring is 600 km out: few beacons within 300 km


# --------------------------------------------------------------------------------------
# Drift and scenarios


def test_truth_runs_from_launch_to_end_fix():
    beacons, floats = dimes_scenario(("767",))
    info = floats[0]
    # Also a mission that does not last a whole number of days.
    half = dataclasses.replace(info, float_id="half", end_time=info.end_time - np.timedelta64(13, "h"))
    mission = simulate_mission(beacons, [info, half], DEFAULT_MODEL, np.random.default_rng(12))
    for sf in mission.floats:
        truth, f = sf.truth, sf.info
        assert truth["time"].iloc[0] == f.launch_time and truth["time"].iloc[-1] == f.end_time
        assert truth["time"].dtype == np.dtype("datetime64[ns]")
        assert range_m(truth["lat"].iloc[0], truth["lon"].iloc[0], f.launch_lat, f.launch_lon) < 1.0
        assert range_m(truth["lat"].iloc[-1], truth["lon"].iloc[-1], f.end_lat, f.end_lon) < 1.0
        steps = range_m(truth["lat"][:-1], truth["lon"][:-1], truth["lat"][1:], truth["lon"][1:])
        assert steps.max() < 60e3  # daily steps, no jumps
    assert len(mission.floats[1].truth) == len(mission.floats[0].truth)  # 728 days + the last 11 h
    assert (mission.floats[1].truth["time"].diff().iloc[-1]) == pd.Timedelta(hours=11)


def test_eddy_velocity_has_the_stated_sd_and_timescale():
    _, floats = synthetic_scenario(days=4000, rng=1)
    truth = simulate_drift(floats[0], np.random.default_rng(13), eddy_speed_km_per_day=4.0, eddy_timescale_days=10.0)
    lat, lon = truth["lat"].to_numpy(), truth["lon"].to_numpy()
    east, north = local_offsets_km(lat[1:], lon[1:], lat[:-1], lon[:-1])
    for v in (east, north):
        fluct = v - v.mean()
        assert abs(fluct.std() - 4.0) < 0.6
        lag1 = np.corrcoef(fluct[:-1], fluct[1:])[0, 1]
        assert abs(lag1 - np.exp(-0.1)) < 0.03  # T = 20 days would give 0.951


def test_no_end_time_needs_days():
    beacons, floats = synthetic_scenario()
    info = dataclasses.replace(floats[0], end_time=NAT, end_lat=np.nan, end_lon=np.nan)
    with pytest.raises(ValueError, match="days"):
        simulate_mission(beacons, [info], DEFAULT_MODEL, np.random.default_rng(0))


def test_inactive_beacons_are_never_heard():
    beacons, floats = dimes_scenario(("767",))
    model = model_with(detection_range_km=0.0, clutter_rate=0.1)
    sf = simulate_mission(beacons, roomy(floats), model, np.random.default_rng(14), days=450).floats[0]
    start = dict(zip(beacons.beacon_id, beacons.start, strict=True))
    late = {b for b, s in start.items() if s > sf.info.launch_time}
    assert late == {"US2-1", "US2-2", "UK1-1", "UK1-2", "UK1-3", "UK1-4"}
    heard_late = set()
    for w in sf.record.windows:
        for lab in w.beacon_id:
            if lab is not None:
                assert start[lab] <= w.time, (lab, w.time)
                heard_late |= {lab} & late
    assert len(heard_late) >= 3  # they are heard once deployed (the far UK1s arrive after the window)


def test_dimes_scenario_facts():
    beacons, floats = dimes_scenario(window_open_s=3600.0)
    assert len(beacons) == 12
    i = beacons.index_of()
    assert beacons.offset_s[i["US1-1"]] == 300.0 and beacons.offset_s[i["UK1-3"]] == 2700.0
    assert beacons.start[i["US2-1"]] == np.datetime64("2010-02-02T00:00", "ns")
    assert np.all(np.isnat(beacons.end))
    assert [f.float_id for f in floats] == ["float759", "float767", "float811"]
    f759 = floats[0]
    assert f759.launch_time == np.datetime64("2009-02-04T00:00", "ns")
    assert f759.end_time == np.datetime64("2009-11-29T00:00", "ns")
    assert (f759.clock_offset_start_s, f759.clock_offset_end_s) == (1.0, -2.0)
    assert (f759.window_s, f759.max_signals) == (4200.0, 4)
    assert dimes_scenario(("float811",))[1][0].float_id == "float811"
    with pytest.raises(ValueError, match="unknown DIMES float"):
        dimes_scenario(("123",))


def test_summary_columns():
    mission = small_mission(seed=2)
    table = summarize(mission)
    assert list(table["float_id"]) == ["sim1", "sim2", "noend"]
    assert (table["windows"] == 25).all()
    assert ((table["clutter_fraction"] >= 0) & (table["clutter_fraction"] <= 1)).all()


def test_days_cuts_the_mission_consistently_at_the_simulated_track_end(tmp_path):
    """`simulate --scenario dimes --days 60` kept the real end fix two years
    later, so every float's end fix lay hundreds of km from where its record stops."""
    from click.testing import CliRunner

    from rafostrack.cli import main

    result = CliRunner().invoke(main, ["simulate", str(tmp_path), "--scenario", "dimes", "--days", "60"])
    assert result.exit_code == 0, result.output
    _, infos, records, _ = read_back(tmp_path, DEFAULT_MODEL)
    full = {f.float_id: f for f in dimes_scenario()[1]}
    for fid, info in infos.items():
        truth = pd.read_csv(tmp_path / "truth" / f"{fid}.csv")
        last_window = records[fid].windows[-1].time
        assert info.end_time == last_window == full[fid].launch_time + np.timedelta64(60, "D")
        assert pd.Timestamp(truth["time"].iloc[-1]).tz_localize(None) == pd.Timestamp(last_window)
        assert range_m(truth["lat"].iloc[-1], truth["lon"].iloc[-1], info.end_lat, info.end_lon) < 1.0
        # the float clock keeps its linear model: the end offset is the one at the new end
        expected = full[fid].clock_offset_s(np.datetime64(info.end_time))
        assert info.clock_offset_end_s == pytest.approx(float(expected), abs=0.01)


def test_data_samples_is_files_and_the_package_carries_an_equal_copy(tmp_path):
    """data/samples was a link into the package: `cp -r data/samples mymission` copied a
    dangling link. It is a directory of files (what `make sample` writes, the one source);
    the package data (`sample_mission_dir`) is a copy of it, byte for byte, all installed."""
    import shutil
    import tomllib
    from pathlib import PurePosixPath

    from rafostrack.sim.scenarios import sample_mission_dir

    root = Path(__file__).resolve().parents[1]
    samples = root / "data" / "samples"
    assert samples.is_dir() and not samples.is_symlink()
    assert not [p for p in samples.rglob("*") if p.is_symlink()]

    def files(top: Path) -> dict[str, bytes]:
        return {p.relative_to(top).as_posix(): p.read_bytes() for p in sorted(top.rglob("*")) if p.is_file()}

    ours, package = files(samples), files(sample_mission_dir())
    assert ours.keys() == package.keys()
    differ = [name for name in ours if ours[name] != package[name]]
    assert not differ, f"{differ}: rafostrack/data/samples differs from data/samples; run `make sample` (it copies)"
    globs = tomllib.loads((root / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]["rafostrack"]
    paths = [PurePosixPath("data/samples", name) for name in ours]
    missing = [p for p in paths if not any(len(p.parts) == len(PurePosixPath(g).parts) and p.match(g) for g in globs)]
    assert not missing, f"{missing}: not in pyproject.toml's package-data (not installed)"
    mission = Path(shutil.copytree(samples, tmp_path / "mymission"))  # what a user does
    assert files(mission) == ours


def test_dimes_n_floats_is_honoured_up_to_the_scenarios_three(tmp_path):
    """`simulate --scenario dimes --n-floats N` wrote 3 floats whatever N."""
    from click.testing import CliRunner

    from rafostrack.cli import main

    def floats(args: list[str]) -> list[str]:
        out = tmp_path / str(len(list(tmp_path.iterdir())))
        result = CliRunner().invoke(main, ["simulate", str(out), "--scenario", "dimes", "--days", "2", *args])
        assert result.exit_code == 0, result.output
        return list(pd.read_csv(out / "floats.csv")["float_id"])

    assert floats(["--n-floats", "2"]) == ["float759", "float767"]
    assert floats([]) == ["float759", "float767", "float811"]  # the default: all of them
    result = CliRunner().invoke(main, ["simulate", str(tmp_path / "x"), "--scenario", "dimes", "--n-floats", "4"])
    assert result.exit_code == 2
    assert result.output.strip().splitlines() == [
        "rafostrack: error: --n-floats 4: the dimes scenario has 3 floats (float759, float767, float811); "
        "expected at most 3 (--scenario synthetic makes any number)"
    ]
    assert not (tmp_path / "x").exists()


def test_echoes_arrive_after_their_source_and_carry_its_label():
    """With echo_fraction e, a detected source's signal comes a second time, Exp(tau) later,
    labelled with the source: the windows that hold a source twice are about e of those
    that hold it."""
    beacons, floats = synthetic_scenario(days=150, rng=4)
    model = model_with(echo_fraction=0.3, multipath_delay_s=15.0, clutter_rate=0.05, detection_range_km=0.0)
    mission = simulate_mission(beacons, roomy(floats), model, np.random.default_rng(11))
    twice = once = 0
    delays = []
    for sf in mission.floats:
        for w in sf.record.windows:
            labels = [b for b in (w.beacon_id or ()) if b is not None]
            for b in set(labels):
                times = w.toa_s[[k for k, x in enumerate(w.beacon_id or ()) if x == b]]
                once += 1
                if len(times) == 2:
                    twice += 1
                    delays.append(times[1] - times[0])
    assert twice / once == pytest.approx(0.3, abs=0.03)
    assert np.mean(delays) == pytest.approx(15.0, rel=0.1)
