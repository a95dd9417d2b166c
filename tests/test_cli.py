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
from support import copy_mission

from rafostrack.cli import main
from rafostrack.errors import InputError
from rafostrack.io.writers import read_metadata


@pytest.fixture(scope="module")
def mission_dir(tmp_path_factory):
    """A simulated mission of 12 days: what the commands write does not depend on its length."""
    out = tmp_path_factory.mktemp("mission")
    result = CliRunner().invoke(main, ["simulate", str(out), "--days", "12", "--seed", "5"])
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
        "status",
    ]
    assert set(track["status"]) <= {"ok", "ambiguous", "recovered", "unsupported"}
    assert str(track["time"].dtype) == "datetime64[ns, UTC]"
    labels = pd.read_parquet(out / "labels.parquet")
    assert list(labels.columns) == ["float_id", "time", "rank", "toa_s", "beacon_id", "prob", "p_clutter"]

    meta = read_metadata(out / "track.parquet")
    assert meta["likelihood"] == "ranked" and meta["engine"] == "exact" and meta["motion"] == "ou"
    assert meta["config"]["filter"]["particles"] == 300
    assert meta["estimate"] == "smoothed"
    run = json.loads((out / "run.json").read_text())
    assert run["counts"]["windows"] == len(track) and run["counts"]["toas"] == len(labels)
    assert set(run["inputs"]) == {"float_file", "beacons", "floats"}
    assert not list(out.glob(".*tmp"))  # no temporary files left behind


def test_mission_config_and_flags_are_layered(mission_dir, tmp_path):
    float_file = _float_file(mission_dir)
    cfg = tmp_path / "extra.toml"
    cfg.write_text("[filter]\nparticles = 120\nengine = 'bp'\n")
    args = [
        "track",
        str(float_file),
        "--out",
        str(tmp_path),
        "--config",
        str(cfg),
        "--likelihood",
        "unranked",
        "--no-plots",
    ]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    run = json.loads((tmp_path / float_file.stem / "run.json").read_text())
    assert run["likelihood"] == "unranked" and run["engine"] == "bp" and run["config"]["filter"]["particles"] == 120
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
        (["track", "{f}", "--engine", "magic"], "[filter] engine: must be one of exact, bp, abc, got 'magic'"),
        (
            ["track", "{f}", "--method", "bp"],
            "--method was split into two options: use --likelihood ranked --engine bp",
        ),
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


@pytest.mark.parametrize("command", ["track", "legs"])
def test_a_directory_given_as_the_float_file_is_named_as_one(mission_dir, tmp_path, command):
    """`rafostrack track DIR` said "file not found" for a directory that exists."""
    result = CliRunner().invoke(main, [command, str(mission_dir), "--out", str(tmp_path)])
    assert result.exit_code == 2
    example = mission_dir / _float_file(mission_dir).name
    assert result.output.strip().splitlines() == [
        f"rafostrack: error: {mission_dir}: is a directory; expected one float's arrival file (e.g. {example}); "
        f"to track every float in it: rafostrack batch {mission_dir} --out OUT"
    ]


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


@pytest.mark.slow
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
        args = [exe, "track", str(float_file), "--out", str(out), "--particles", "150", "--no-plots", "--also-filtered"]
        subprocess.run(args, check=True, capture_output=True, env=env)
        digests.append({p.name: p.read_bytes() for p in sorted((out / float_file.stem).glob("*.parquet"))})
    assert digests[0] == digests[1]


@pytest.mark.reliability
@pytest.mark.parametrize(
    ("file", "text", "needle"),
    [
        ("beacons.csv", "beacon_id,lat,lon\nB1,95,0\n", "beacons.csv: line 2: field 'lat': expected a finite value"),
        ("beacons.csv", "beacon_id;lat;lon\nB1;1;2\n", "beacons.csv: line 1: columns are separated by ';'"),
        ("floats.csv", "", "floats.csv: file is empty"),
        ("sim1.csv", "time,toa_s\n2010-01-02,abc\n", "sim1.csv: line 2: field 'toa_s': expected a number"),
        ("rafostrack.toml", "[model]\nclutter_rte = 1\n", "unknown key [model] clutter_rte (did you mean"),
        ("rafostrack.toml", '[model]\np_detect = "0.9"\n', 'got the string "0.9" (remove the quotes)'),
    ],
)
def test_cli_input_errors_exit_2_one_line_no_traceback(sim_mission_dir, tmp_path, file, text, needle):
    m = copy_mission(sim_mission_dir, tmp_path / "m")
    (m / file).write_text(text)
    result = CliRunner().invoke(main, ["track", str(m / "sim1.csv"), "--out", str(tmp_path / "out")])
    assert result.exit_code == 2
    assert result.stderr.startswith("rafostrack: error: ") and needle in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and "Traceback" not in result.output
    assert not (tmp_path / "out" / "sim1").exists()  # nothing half-written


@pytest.mark.reliability
def test_cli_error_in_a_subprocess(sim_mission_dir, tmp_path):
    """The installed entry point, as a user runs it: exit code 2, one line on stderr."""
    exe = shutil.which("rafostrack", path=str(Path(sys.executable).parent))
    assert exe is not None
    m = copy_mission(sim_mission_dir, tmp_path / "m")
    (m / "beacons.csv").write_text("beacon_id,lat,lon\nB1,-58,-100\nB1,-57,-100\n")
    proc = subprocess.run(
        [exe, "track", str(m / "sim1.csv"), "--out", str(tmp_path / "out")], capture_output=True, text=True, check=False
    )
    assert proc.returncode == 2
    assert proc.stderr == (
        f"rafostrack: error: {m / 'beacons.csv'}: line 3: duplicate beacon_id 'B1' (first on line 2); "
        "field 'beacon_id': expected each id once\n"
    )
    assert proc.stdout == ""


@pytest.mark.reliability
def test_cli_debug_shows_the_traceback(sim_mission_dir, tmp_path):
    m = copy_mission(sim_mission_dir, tmp_path / "m")
    (m / "floats.csv").write_text("")
    result = CliRunner().invoke(main, ["--debug", "track", str(m / "sim1.csv"), "--out", str(tmp_path / "out")])
    assert isinstance(result.exception, InputError) and "file is empty" in str(result.exception)


@pytest.mark.reliability
def test_cli_warnings_listed_in_run_json_and_stderr(sim_mission_dir, tmp_path):
    m = copy_mission(sim_mission_dir, tmp_path / "m")
    arrivals = pd.read_csv(m / "sim1.csv", dtype=str, keep_default_na=False)
    times = sorted(arrivals["time"].unique())
    extra = pd.DataFrame(
        {
            "time": [times[3], times[5], *[times[7]] * 5],
            "toa_s": [arrivals["toa_s"].iloc[0], "-12", "10", "20", "30", "40", "50"],
            "beacon_id": [""] * 7,
        }
    )
    pd.concat([arrivals, arrivals.iloc[:1], extra]).to_csv(m / "sim1.csv", index=False)
    beacons = pd.read_csv(m / "beacons.csv", dtype=str, keep_default_na=False)
    beacons["end"] = times[-3]  # every beacon stops: the last two windows have none
    beacons.to_csv(m / "beacons.csv", index=False)

    out = tmp_path / "out"
    result = CliRunner().invoke(main, ["track", str(m / "sim1.csv"), "--out", str(out), "--no-plots"])
    assert result.exit_code == 0, result.output
    run = json.loads((out / "sim1" / "run.json").read_text())
    text = " | ".join(run["warnings"])
    for needle in (
        "duplicate row(s) (same time and toa_s) dropped",
        "1 TOA(s) outside the window [0, 4200] s dropped (1 negative",
        "held more than max_signals=4 TOAs; kept the earliest",
        "2 window(s) with no active beacon",
    ):
        assert needle in text
    assert run["counts"]["warnings"] == len(run["warnings"]) >= 4
    printed = [line for line in result.stderr.splitlines() if line.startswith("rafostrack: warning: ")]
    assert printed == [f"rafostrack: warning: {w}" for w in run["warnings"]]
    assert f"rafostrack: {len(run['warnings'])} warning(s), also listed in {out / 'sim1' / 'run.json'}" in result.stderr


# --------------------------------------------------------------------------------------
# Usage errors are the documented one line too


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (
            ["track", "{f}", "--particles", "10.5"],
            "track: invalid value for '--particles': '10.5' is not a valid integer. (see 'rafostrack track --help')",
        ),
        (["batch", "{m}", "--out", "{o}", "--jobs", "0"], "--jobs"),
        (["track", "{f}", "--bogus-option"], "track: no such option '--bogus-option'"),
        (["trak", "{f}"], "no such command 'trak'. did you mean 'track'? (see 'rafostrack --help')"),
        (["track"], "missing argument 'FLOAT_FILE'"),
    ],
)
def test_usage_errors_are_one_line_and_exit_2(mission_dir, tmp_path, args, needle):
    subs = {"{f}": str(_float_file(mission_dir)), "{m}": str(mission_dir), "{o}": str(tmp_path / "o")}
    args = [subs.get(a, a) for a in args]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("rafostrack: error: "), result.output
    assert needle.lower() in lines[0].lower()
    assert "Usage:" not in result.output


def test_debug_after_the_subcommand(sim_mission_dir, tmp_path):
    m = copy_mission(sim_mission_dir, tmp_path / "m")
    (m / "floats.csv").write_text("")
    result = CliRunner().invoke(main, ["track", str(m / "sim1.csv"), "--out", str(tmp_path / "out"), "--debug"])
    assert isinstance(result.exception, InputError) and "file is empty" in str(result.exception)


def test_missing_column_suggestion_goes_from_the_typo_to_the_name(sim_mission_dir, tmp_path):
    m = copy_mission(sim_mission_dir, tmp_path / "m")
    text = (m / "sim1.csv").read_text().replace("time,toa_s,", "time,toa,", 1)
    (m / "sim1.csv").write_text(text)
    result = CliRunner().invoke(main, ["track", str(m / "sim1.csv"), "--out", str(tmp_path / "out")])
    assert result.exit_code == 2
    assert "missing required column 'toa_s'" in result.output
    assert "did you mean 'toa_s'?" in result.output and "did you mean 'toa'?" not in result.output


def test_missing_floats_csv_names_launch(sim_mission_dir, tmp_path):
    m = copy_mission(sim_mission_dir, tmp_path / "m")
    (m / "floats.csv").unlink()
    result = CliRunner().invoke(main, ["track", str(m / "sim1.csv"), "--out", str(tmp_path / "out")])
    assert result.exit_code == 2
    assert "floats.csv: file not found" in result.output and "--launch LAT,LON" in result.output


# --------------------------------------------------------------------------------------
# Progress on a terminal; the printed time includes the plots


def _slow_plots(seconds: float):
    import time

    def write_plots(outdir, *args, **kwargs):
        time.sleep(seconds)
        return []

    return write_plots


def test_printed_time_includes_the_plots(sim_mission_dir, tmp_path, monkeypatch):
    import re
    import time

    import rafostrack.plots

    monkeypatch.setattr(rafostrack.plots, "write_plots", _slow_plots(1.0))
    started = time.perf_counter()
    result = CliRunner().invoke(main, ["track", str(sim_mission_dir / "sim1.csv"), "--out", str(tmp_path)])
    wall = time.perf_counter() - started
    assert result.exit_code == 0, result.output
    printed = float(re.search(r", ([0-9.]+) s -> ", result.output).group(1))
    assert printed >= wall - 0.5  # the whole run, the 1 s of plots included
    run = json.loads((tmp_path / "sim1" / "run.json").read_text())
    assert run["runtime_s"] >= run["track_s"] + 1.0


def test_progress_bar_on_a_terminal_only(sim_mission_dir, tmp_path, monkeypatch):
    import rafostrack.plots
    import rafostrack.run.progress

    monkeypatch.setattr(rafostrack.plots, "write_plots", _slow_plots(0.7))
    args = ["track", str(sim_mission_dir / "sim1.csv"), "--out", str(tmp_path)]
    quiet = CliRunner().invoke(main, args)
    assert quiet.exit_code == 0 and "drawing plots" not in quiet.output  # not a terminal: no bar
    monkeypatch.setattr(rafostrack.run.progress, "is_terminal", lambda stream: True)
    shown = CliRunner().invoke(main, args)
    assert shown.exit_code == 0, shown.output
    for phase in rafostrack.run.progress.PHASES:
        assert phase in shown.output
    assert "sim1" in shown.output.splitlines()[-1]  # the summary line still ends the output


def test_config_command_prints_the_merged_configuration_with_sources(sim_mission_dir, tmp_path):
    """`rafostrack config [MISSION]`."""
    import tomllib

    from rafostrack.config import load_config

    extra = tmp_path / "extra.toml"
    extra.write_text("[filter]\nseed = 7\n")
    args = ["config", str(sim_mission_dir), "--config", str(extra), "--p-detect", "0.6"]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    mission_toml = str(sim_mission_dir / "rafostrack.toml")

    def line(key: str) -> str:
        return next(x for x in lines if x.startswith(f"{key} = "))

    assert line("particles").endswith(f"# {mission_toml}")  # the mission's rafostrack.toml
    assert line("seed").startswith("seed = 7") and line("seed").endswith(f"# {extra}")
    assert line("p_detect").startswith("p_detect = 0.6") and line("p_detect").endswith("# command line")
    assert line("resampling").endswith("# default")
    expected = load_config([sim_mission_dir / "rafostrack.toml", extra], {"model": {"p_detect": 0.6}})
    assert tomllib.loads(result.output) == expected.to_dict()  # valid TOML: usable as --config
    bad = CliRunner().invoke(main, ["config", str(tmp_path / "nope")])
    assert bad.exit_code == 2 and "rafostrack: error:" in bad.output
