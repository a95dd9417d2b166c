"""`rafostrack.run.one_float`: one float end to end, reproducible to the byte."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner
from support import copy_mission, parquet_bytes, timing_free

from rafostrack.cli import main

pytestmark = pytest.mark.reliability


def test_wild_toa_window_stays_finite(sim_mission_dir, tmp_path):
    """Numerical safety: a window of TOAs no beacon can explain (all ~zero likelihood
    under the sources) gives finite weights and a finite track, the TOAs labelled clutter."""
    m = copy_mission(sim_mission_dir, tmp_path / "m")
    arrivals = pd.read_csv(m / "sim1.csv", dtype=str, keep_default_na=False)
    wild = arrivals["time"] == sorted(arrivals["time"].unique())[10]
    arrivals.loc[wild, "toa_s"] = [f"{4150 + i}" for i in range(int(wild.sum()))]
    arrivals.to_csv(m / "sim1.csv", index=False)
    args = ["track", str(m / "sim1.csv"), "--out", str(tmp_path / "out"), "--no-plots", "--toa-sigma-s", "0.2"]
    result = CliRunner().invoke(main, [*args, "--clutter-rate", "0.01"])
    assert result.exit_code == 0, result.output
    track = pd.read_parquet(tmp_path / "out" / "sim1" / "track.parquet")
    assert np.isfinite(track[["lat", "lon", "sd_km", "ess", "loglik"]].to_numpy()).all()


def test_same_inputs_give_the_same_parquet_bytes(sim_mission_dir, tmp_path):
    args = ["track", str(sim_mission_dir / "sim1.csv"), "--no-plots", "--particles", "200", "--seed", "11"]
    for name in ("a", "b"):
        result = CliRunner().invoke(main, [*args, "--out", str(tmp_path / name)])
        assert result.exit_code == 0, result.output
    a, b = parquet_bytes(tmp_path / "a" / "sim1"), parquet_bytes(tmp_path / "b" / "sim1")
    assert {"track.parquet", "labels.parquet"} <= set(a) and a == b
    run_a, run_b = (json.loads((tmp_path / n / "sim1" / "run.json").read_text()) for n in ("a", "b"))
    assert "runtime_s" in run_a and timing_free(run_a) == timing_free(run_b)


def _names(directory) -> set[str]:
    return {p.name for p in directory.iterdir()}


def test_rerun_leaves_only_the_current_runs_files_atomically(sim_mission_dir, tmp_path, monkeypatch):
    """A rerun into the same directory left the previous run's files (an old
    track_filtered.parquet, old PNGs) beside the new ones. The float directory is now built
    beside the old one and swapped in whole; a run that fails leaves the old one untouched."""
    import rafostrack.plots

    float_file = str(sim_mission_dir / "sim1.csv")
    out = tmp_path / "out"
    first = CliRunner().invoke(main, ["track", float_file, "--out", str(out), "--also-filtered", "--no-smooth"])
    assert first.exit_code == 0, first.output
    old = {p.name: p.read_bytes() for p in (out / "sim1").iterdir()}
    assert {"track.png", "track.parquet"} <= set(old)

    # A rerun that fails half-way (while drawing plots) leaves the previous result whole.
    def broken(*args, **kwargs):
        raise RuntimeError("disk full while drawing")

    monkeypatch.setattr(rafostrack.plots, "write_plots", broken)
    failed = CliRunner().invoke(main, ["track", float_file, "--out", str(out), "--particles", "150"])
    assert failed.exit_code == 1
    assert {p.name: p.read_bytes() for p in (out / "sim1").iterdir()} == old
    assert _names(out) == {"sim1"}  # no staging or trash directory left behind
    monkeypatch.undo()

    rerun = CliRunner().invoke(main, ["track", float_file, "--out", str(out), "--no-plots", "--particles", "150"])
    assert rerun.exit_code == 0, rerun.output
    assert _names(out / "sim1") == {"track.parquet", "labels.parquet", "modes.parquet", "run.json"}
    assert _names(out) == {"sim1"}
