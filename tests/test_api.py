"""The Python API: `rafostrack.track` from files and DataFrames; README's example runs."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
from matplotlib.figure import Figure

import rafostrack
from rafostrack.errors import InputError

ROOT = Path(__file__).resolve().parents[1]


README_CHECKS = """
import json
seen = {"rows": len(r.track), "columns": list(r.track.columns[:4]), "windows": r.run_info["counts"]["windows"]}
print(json.dumps({**seen, "figure": type(fig).__name__, "float_id": r2.float_id, "rows2": len(r2.track)}))
"""


@pytest.mark.slow
def test_readme_example_runs_from_any_folder(tmp_path):
    """README's Python example as a user runs it: in a fresh process, in a folder that is not
    the clone's (its paths were relative to the clone's root: file not found elsewhere)."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    section = text[text.index("## Python API") :]
    code = re.search(r"```python\n(.*?)```", section, re.DOTALL).group(1)
    (tmp_path / "example.py").write_text(code + README_CHECKS, encoding="utf-8")
    env = {**os.environ, "MPLBACKEND": "Agg"}
    proc = subprocess.run([sys.executable, "example.py"], cwd=tmp_path, env=env, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-2000:]
    seen = json.loads(proc.stdout.strip().splitlines()[-1])
    assert seen["columns"] == ["float_id", "time", "lat", "lon"] and seen["rows"] == seen["windows"] == 404
    assert seen["figure"] == "Figure" and seen["float_id"] == "float811" and 40 < seen["rows2"] < 80
    assert "windows," in proc.stdout


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
    with pytest.raises(InputError, match=r"^beacons DataFrame: row 0: field 'lat': expected a number, got 'abc'"):
        rafostrack.track(frames["sim1"], beacons=frames["beacons"], floats=frames["floats"])


def _frames(mission: Path, **read) -> dict[str, pd.DataFrame]:
    return {name: pd.read_csv(mission / f"{name}.csv", **read) for name in ("sim1", "beacons", "floats")}


def test_frame_messages_name_the_argument_and_row_not_a_temporary_file(sim_mission_dir, tmp_path):
    """Errors and warnings named the temporary mission (/tmp/rafostrack-xxxx/sim1.csv, line 5);
    a user passed DataFrames: they name the argument and the row's index label."""
    frames = _frames(sim_mission_dir, dtype=str)
    arrivals = frames["sim1"].iloc[10:30]  # a slice: index labels 10..29, not positions
    bad = arrivals.copy()
    bad.loc[13, "time"] = "yesterday"  # a text the reader refuses (not a pandas error while writing)
    with pytest.raises(InputError) as caught:
        rafostrack.track(bad, beacons=frames["beacons"], floats=frames["floats"])
    assert str(caught.value).startswith("arrivals DataFrame: row 13: field 'time': expected an ISO-8601 time")
    with pytest.raises(InputError, match=r"^arrivals DataFrame: columns: missing required column 'toa_s'"):
        rafostrack.track(arrivals.rename(columns={"toa_s": "toa"}), beacons=frames["beacons"], floats=frames["floats"])
    floats = frames["floats"].assign(launch_lat="x")
    with pytest.raises(InputError, match=r"^floats DataFrame: row 0: field 'launch_lat': expected a number, got 'x'"):
        rafostrack.track(arrivals, beacons=frames["beacons"], floats=floats)
    with pytest.raises(InputError, match=r"^rafostrack\.track: arrivals given as a DataFrame need beacons="):
        rafostrack.track(arrivals, floats=frames["floats"])
    twice = pd.concat([arrivals, arrivals.loc[[15]]])  # one duplicate row, warned about
    run = rafostrack.track(
        twice, beacons=frames["beacons"], floats=frames["floats"], out=tmp_path, plots=False, particles=60, smooth=False
    )
    warning = "arrivals DataFrame: 1 duplicate row(s) (same time and toa_s) dropped (first at row 15)"
    assert warning in run.run_info["warnings"]
    written = (tmp_path / "sim1" / "run.json").read_text()
    assert "rafostrack-" not in written and warning in written


def test_which_float_the_arrivals_are(sim_mission_dir):
    """Given the whole floats table, the API asked for float_id 'float' (a name it made up):
    it says which floats the table holds, or takes the float the arrivals name."""
    frames = _frames(sim_mission_dir)
    second = frames["floats"].assign(float_id="sim2")
    floats = pd.concat([frames["floats"], second], ignore_index=True)
    arrivals = frames["sim1"].head(60)
    with pytest.raises(InputError) as caught:
        rafostrack.track(arrivals, beacons=frames["beacons"], floats=floats)
    assert str(caught.value) == (
        "rafostrack.track: the floats DataFrame holds 2 floats (sim1, sim2) and the arrivals DataFrame names none "
        "(no float_id column); expected one float's arrivals and which float they are: give float_id= "
        "(e.g. float_id='sim1'), or pass that float's row of the floats table"
    )
    with pytest.raises(InputError, match=r"float_id 'sim3' is not in the floats DataFrame; it holds sim1, sim2$"):
        rafostrack.track(arrivals, beacons=frames["beacons"], floats=floats, float_id="sim3")
    options = {"particles": 60, "smooth": False, "calibrate_enabled": False}
    both = pd.concat([arrivals.assign(float_id="sim1"), arrivals.assign(float_id="sim2")])
    with pytest.raises(InputError, match=r"the arrivals DataFrame holds the arrivals of 2 floats \(sim1, sim2\)"):
        rafostrack.track(both, beacons=frames["beacons"], floats=floats, **options)
    picked = rafostrack.track(both, beacons=frames["beacons"], floats=floats, float_id="sim2", **options)
    named = rafostrack.track(arrivals.assign(float_id="sim2"), beacons=frames["beacons"], floats=floats, **options)
    assert picked.float_id == named.float_id == "sim2"
    pd.testing.assert_frame_equal(picked.track, named.track)


def test_tables_are_utc_like_the_parquet_files(sim_mission_dir, tmp_path):
    """The API's times were tz-naive while track.parquet's are UTC."""
    run = rafostrack.track(sim_mission_dir / "sim1.csv", out=tmp_path, plots=False, particles=60, smooth=False)
    for name in ("track", "labels", "modes"):
        table = getattr(run, name)
        assert str(table["time"].dt.tz) == "UTC", name
        written = pd.read_parquet(tmp_path / "sim1" / f"{name}.parquet")["time"]
        pd.testing.assert_series_equal(table["time"].dt.as_unit("ns"), written.dt.as_unit("ns"))
    assert isinstance(run.plot(), Figure)


def test_a_directory_is_named_as_one(sim_mission_dir):
    """`rafostrack.track(DIR)` said "file not found" for a directory that exists."""
    with pytest.raises(InputError, match=r"is a directory; expected one float's arrival file \(e\.g\. .*sim1\.csv\)$"):
        rafostrack.track(sim_mission_dir)


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


def test_the_editable_install_is_a_plain_path_entry():
    """Every `pip install -e .` printed setuptools' warning block about folders named like the
    package: without `package-dir`, setuptools installs a meta path finder and warns. With it
    (the flat layout said explicitly), a .pth file puts the repository on sys.path, what the
    Makefile used to write by hand."""
    import tomllib

    setuptools = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    assert setuptools["package-dir"] == {"": "."}
    assert "purelib" not in (ROOT / "Makefile").read_text()  # no .pth file written by hand


def test_the_api_imports_from_the_folder_that_holds_a_clone_named_rafostrack(tmp_path):
    """Run beside a clone named `rafostrack` (the folder a newcomer saves the README's
    example in), `import rafostrack` finds the installed package, not the clone folder as
    an empty namespace package (the Makefile's editable install puts the repository on
    sys.path)."""
    (tmp_path / "rafostrack").mkdir()  # what a clone looks like from its parent: no __init__.py
    done = subprocess.run(
        [sys.executable, "-c", "import rafostrack; print(callable(rafostrack.track))"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "True"
