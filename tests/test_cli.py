"""The command line end to end: simulate a mission, track it, read the outputs back."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
from click.testing import CliRunner

from rafostrack.cli import main
from rafostrack.outputs import read_metadata


@pytest.fixture(scope="module")
def mission_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("mission")
    result = CliRunner().invoke(main, ["simulate", str(out), "--days", "30", "--seed", "5"])
    assert result.exit_code == 0, result.output
    return out


def _float_file(mission_dir):
    return next(p for p in sorted(mission_dir.glob("*.csv")) if p.name not in ("beacons.csv", "floats.csv"))


def test_track_writes_every_output(mission_dir, tmp_path):
    float_file = _float_file(mission_dir)
    result = CliRunner().invoke(main, ["track", str(float_file), "--out", str(tmp_path), "--particles", "300"])
    assert result.exit_code == 0, result.output
    out = tmp_path / float_file.stem
    names = {p.name for p in out.iterdir()}
    assert names == {
        "track.parquet",
        "labels.parquet",
        "modes.parquet",
        "run.json",
        "track.png",
        "arrivals.png",
        "uncertainty.png",
    }

    track = pd.read_parquet(out / "track.parquet")
    assert list(track.columns) == [
        "float_id",
        "time",
        "lat",
        "lon",
        "sd_km",
        "smaj_km",
        "smin_km",
        "angle_deg",
        "ess",
        "n_signals",
        "loglik",
        "ambiguous",
        "second_mode_km",
    ]
    assert str(track["time"].dtype) == "datetime64[ns, UTC]"
    labels = pd.read_parquet(out / "labels.parquet")
    assert list(labels.columns) == ["float_id", "time", "rank", "toa_s", "beacon_id", "prob", "p_clutter"]

    meta = read_metadata(out / "track.parquet")
    assert meta["method"] == "exact" and meta["config"]["filter"]["particles"] == 300
    assert meta["estimate"] == "smoothed"
    run = json.loads((out / "run.json").read_text())
    assert run["counts"]["windows"] == len(track) and run["counts"]["toas"] == len(labels)
    assert set(run["inputs"]) == {"float_file", "beacons", "floats"}
    assert not list(out.glob(".*tmp"))  # no temporary files left behind


def test_mission_config_and_flags_are_layered(mission_dir, tmp_path):
    float_file = _float_file(mission_dir)
    cfg = tmp_path / "extra.toml"
    cfg.write_text("[filter]\nparticles = 120\nmethod = 'bp'\n")
    args = [
        "track",
        str(float_file),
        "--out",
        str(tmp_path),
        "--config",
        str(cfg),
        "--method",
        "unranked",
        "--no-plots",
    ]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    run = json.loads((tmp_path / float_file.stem / "run.json").read_text())
    assert run["method"] == "unranked" and run["config"]["filter"]["particles"] == 120
    assert str(mission_dir / "rafostrack.toml") in run["config_files"]


def test_no_smooth_and_also_filtered(mission_dir, tmp_path):
    float_file = _float_file(mission_dir)
    base = ["track", str(float_file), "--particles", "200", "--no-plots"]
    result = CliRunner().invoke(main, [*base, "--out", str(tmp_path / "a"), "--also-filtered"])
    assert result.exit_code == 0, result.output
    out = tmp_path / "a" / float_file.stem
    assert read_metadata(out / "track.parquet")["estimate"] == "smoothed"
    assert read_metadata(out / "track_filtered.parquet")["estimate"] == "filtered"
    assert (out / "labels_filtered.parquet").exists()
    result = CliRunner().invoke(main, [*base, "--out", str(tmp_path / "b"), "--no-smooth"])
    assert result.exit_code == 0, result.output
    out = tmp_path / "b" / float_file.stem
    assert read_metadata(out / "track.parquet")["estimate"] == "filtered"
    assert not (out / "track_filtered.parquet").exists()
    # The filtered estimate does not depend on whether the smoother runs after it.
    a = pd.read_parquet(tmp_path / "a" / float_file.stem / "track_filtered.parquet")
    b = pd.read_parquet(out / "track.parquet")
    pd.testing.assert_frame_equal(a, b)


def test_launch_override_without_floats_table(mission_dir, tmp_path):
    mission = tmp_path / "m"
    mission.mkdir()
    float_file = _float_file(mission_dir)
    shutil.copy(float_file, mission / float_file.name)
    shutil.copy(mission_dir / "beacons.csv", mission / "beacons.csv")
    floats = pd.read_csv(mission_dir / "floats.csv")
    row = floats[floats["float_id"] == float_file.stem].iloc[0]
    args = ["track", str(mission / float_file.name), "--launch", f"{row.launch_lat},{row.launch_lon}"]
    result = CliRunner().invoke(main, [*args, "--out", str(tmp_path / "out"), "--no-plots", "--particles", "200"])
    assert result.exit_code == 0, result.output


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["track", "nope/float1.csv"], "nope/float1.csv: file not found"),
        (["track", "{f}", "--method", "magic"], "Invalid value for '--method'"),
        (["track", "{f}", "--launch", "abc"], "expected LAT,LON"),
        (["track", "{f}", "--clutter-rate", "-1"], "[model] clutter_rate: must be > 0"),
    ],
)
def test_user_errors_are_one_line_and_exit_2(mission_dir, tmp_path, args, needle):
    args = [a.replace("{f}", str(_float_file(mission_dir))) for a in args] + ["--out", str(tmp_path)]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 2
    assert needle in result.output
    assert "Traceback" not in result.output


def test_console_script_runs(mission_dir, tmp_path):
    """The installed entry point, as a user runs it."""
    exe = shutil.which("rafostrack", path=str(Path(sys.executable).parent))
    assert exe is not None
    float_file = _float_file(mission_dir)
    proc = subprocess.run(
        [exe, "track", str(float_file), "--out", str(tmp_path), "--particles", "100", "--no-plots"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    assert float_file.stem in proc.stdout


def test_outputs_do_not_depend_on_the_thread_count(mission_dir, tmp_path):
    """Same inputs and seed, 1 or 2 math-library threads: byte-identical Parquet files."""
    exe = shutil.which("rafostrack", path=str(Path(sys.executable).parent))
    float_file = _float_file(mission_dir)
    digests = []
    for threads in ("1", "2"):
        env = {
            **os.environ,
            **{k: threads for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")},
        }
        out = tmp_path / threads
        args = [exe, "track", str(float_file), "--out", str(out), "--particles", "400", "--no-plots", "--also-filtered"]
        subprocess.run(args, check=True, capture_output=True, env=env)
        digests.append({p.name: p.read_bytes() for p in sorted((out / float_file.stem).glob("*.parquet"))})
    assert digests[0] == digests[1]
