"""The Python API: `rafostrack.track` from files and DataFrames; README's example runs."""

from __future__ import annotations

import os
import re
from pathlib import Path

import pandas as pd
import pytest
from matplotlib.figure import Figure

import rafostrack
from rafostrack.errors import InputError

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_readme_example_runs(monkeypatch, capsys):
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    section = text[text.index("## Python API") :]
    code = re.search(r"```python\n(.*?)```", section, re.DOTALL).group(1)
    monkeypatch.chdir(ROOT)
    namespace: dict = {}
    exec(compile(code, "README.md (Python API)", "exec"), namespace)
    r, r2 = namespace["r"], namespace["r2"]
    assert list(r.track.columns[:4]) == ["float_id", "time", "lat", "lon"] and len(r.track) == 404
    assert r.run_info["counts"]["windows"] == 404 and isinstance(namespace["fig"], Figure)
    assert r2.float_id == "float811" and 40 < len(r2.track) < 80
    assert "windows," in capsys.readouterr().out


def test_files_and_frames_give_the_same_track(sim_mission_dir):
    options = {"particles": 120, "calibrate_enabled": False, "seed": 3}
    from_file = rafostrack.track(sim_mission_dir / "sim1.csv", **options)
    frames = {name: pd.read_csv(sim_mission_dir / f"{name}.csv") for name in ("sim1", "beacons", "floats")}
    from_frames = rafostrack.track(
        frames["sim1"], beacons=frames["beacons"], floats=frames["floats"], config={"model": _model(sim_mission_dir)},
        **options,
    )  # fmt: skip
    pd.testing.assert_frame_equal(from_file.track, from_frames.track)
    pd.testing.assert_frame_equal(from_file.labels, from_frames.labels)
    assert from_file.run_info["config"] == from_frames.run_info["config"]
    for kind in ("track", "arrivals", "uncertainty"):
        assert isinstance(from_file.plot(kind), Figure)


def _model(mission: Path) -> dict:
    import tomllib

    return tomllib.loads((mission / "rafostrack.toml").read_text())["model"]


def test_frames_are_checked_like_files(sim_mission_dir):
    frames = {name: pd.read_csv(sim_mission_dir / f"{name}.csv", dtype=str) for name in ("sim1", "beacons", "floats")}
    frames["beacons"].loc[0, "lat"] = "abc"
    with pytest.raises(InputError, match=r"beacons\.csv: line 2: field 'lat': expected a number, got 'abc'"):
        rafostrack.track(frames["sim1"], beacons=frames["beacons"], floats=frames["floats"])


def test_unknown_option_suggests_the_key():
    with pytest.raises(InputError, match=r"unknown option 'particle' \(did you mean 'particles'\?\)"):
        rafostrack.track("nowhere.csv", particle=10)


def test_out_writes_what_the_cli_writes(sim_mission_dir, tmp_path):
    r = rafostrack.track(
        sim_mission_dir / "sim1.csv", out=tmp_path, plots=False, particles=100, calibrate_enabled=False
    )
    assert r.out_dir == tmp_path / "sim1"
    assert {p.name for p in r.out_dir.iterdir()} == {"track.parquet", "labels.parquet", "modes.parquet", "run.json"}
    pd.testing.assert_frame_equal(
        pd.read_parquet(r.out_dir / "track.parquet")[["lat", "lon"]], r.track[["lat", "lon"]].reset_index(drop=True)
    )
    assert os.path.basename(r.run_info["inputs"]["float_file"]["path"]) == "sim1.csv"


def test_make_demo_installs_only_the_package():
    """`make demo` installed the test and Dask extras it does not use."""
    text = (ROOT / "Makefile").read_text()
    rule = re.compile(r"^([^\s:#]+):([^=\n]*)\n((?:\t.*\n)*)", re.MULTILINE)
    targets = {m.group(1): (m.group(2).split(), m.group(3)) for m in rule.finditer(text)}

    def closure(target: str) -> str:
        prereqs, recipe = targets.get(target, ([], ""))
        return recipe + "".join(closure(p) for p in prereqs)

    demo = closure("demo")
    assert "pip install" in demo and "[test" not in demo and "dask" not in demo
    assert "[test,dask]" in closure("test")
