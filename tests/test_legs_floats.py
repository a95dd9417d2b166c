"""`rafostrack legs` end to end on a small simulated float: files, schema, accuracy."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner
from support import simulated_mission_dir

from rafostrack.cli import main
from rafostrack.config import load_config
from rafostrack.legs.floats import leg_prior
from rafostrack.sim.evaluate import position_errors_km
from rafostrack.summaries.estimates import TRACK_COLUMNS


@pytest.fixture(scope="module")
def mission(tmp_path_factory):
    """20 simulated days (seed 1: a float the smoother tracks within a few km), 200 particles."""
    return simulated_mission_dir(tmp_path_factory.mktemp("legs_mission"), seed=1)


@pytest.fixture(scope="module")
def legs_run(mission, tmp_path_factory):
    out = tmp_path_factory.mktemp("legs")
    result = CliRunner().invoke(main, ["legs", str(mission / "sim1.csv"), "--out", str(out), "--iterations", "4000"])
    assert result.exit_code == 0, result.output
    return out / "sim1", mission


def test_writes_legs_track_plot_and_run(legs_run):
    out, _ = legs_run
    assert {p.name for p in out.iterdir()} == {"legs.parquet", "legs_track.parquet", "legs.png", "legs_run.json"}
    legs = pd.read_parquet(out / "legs.parquet")
    for col in ("start", "start_lo", "start_hi", "end", "end_lo", "end_hi", "heading_deg", "heading_lo_deg"):
        assert col in legs
    assert {"speed_km_per_day", "speed_lo_km_per_day", "speed_hi_km_per_day", "heading_hi_deg"} <= set(legs)
    assert (legs["end"] > legs["start"]).all()
    assert (legs["speed_lo_km_per_day"] <= legs["speed_hi_km_per_day"]).all()
    np.testing.assert_array_equal(legs["start"].iloc[1:].to_numpy(), legs["end"].iloc[:-1].to_numpy())
    track = pd.read_parquet(out / "legs_track.parquet")
    assert list(track.columns[: len(TRACK_COLUMNS)]) == list(TRACK_COLUMNS)
    assert track["sd_km"].gt(0).all() and track["ess"].gt(0).all()
    run = json.loads((out / "legs_run.json").read_text())
    assert run["legs"]["map"] == len(legs) and run["iterations"] == 4000
    assert run["timings_s"]["sampler_s"] > 0


def test_leg_track_is_near_the_truth(legs_run):
    out, mission = legs_run
    track = pd.read_parquet(out / "legs_track.parquet")
    track["time"] = track["time"].dt.tz_localize(None)
    truth = pd.read_csv(mission / "truth" / "sim1.csv", parse_dates=["time"])
    truth["time"] = truth["time"].dt.tz_localize(None)
    err = position_errors_km(track, truth)
    assert np.sqrt(np.mean(err**2)) < 5.0


def test_bad_prior_is_one_line_exit_2(mission, tmp_path):
    cfg = tmp_path / "bad.toml"
    cfg.write_text("[legs]\nduration_min_days = 10.0\nduration_max_days = 5.0\n")
    result = CliRunner().invoke(main, ["legs", str(mission / "sim1.csv"), "--out", str(tmp_path), "--config", str(cfg)])
    assert result.exit_code == 2
    assert "duration_min_days" in result.output and len(result.output.strip().splitlines()) == 1


def test_leg_prior_from_config():
    config = load_config()
    assert leg_prior(config).duration_max == config.legs.duration_max_days
