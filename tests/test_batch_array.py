"""The mission rounds of a batch (`batch.array_rounds`): a table with two source offsets
wrong is fitted on every float, the decided table written and tracked with, and a rerun on
the same inputs tracks nothing again."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest
from click.testing import CliRunner
from support import simulated_mission_dir

from rafostrack.batch.array_rounds import fit_mission, round_line
from rafostrack.batch.discover import discover
from rafostrack.cli import main
from rafostrack.io.writers import file_digest

WRONG = {"B3": 30.0, "B5": -40.0}  # s added to the true offsets


def _batch(root: Path, out: Path, *flags: str):
    return CliRunner().invoke(main, ["batch", str(root), "--out", str(out), "--no-plots", "--jobs", "2", *flags])


@pytest.fixture(scope="module")
def faulted(tmp_path_factory) -> tuple[Path, dict[str, float]]:
    """A simulated mission of three 40-day floats whose beacons.csv has two offsets wrong;
    the true offsets."""
    root = tmp_path_factory.mktemp("array") / "root"
    mission = simulated_mission_dir(root / "m", seed=3, days=40, particles=200)
    (root / "m" / "sim1.csv").unlink()  # the simulator's one float: replaced by three below
    result = CliRunner().invoke(main, ["simulate", str(mission), "--days", "40", "--seed", "3", "--n-floats", "3"])
    assert result.exit_code == 0, result.output
    with open(mission / "rafostrack.toml", "a") as fh:
        fh.write("\n[filter]\nparticles = 200\n")
    table = mission / "beacons.csv"
    rows = list(csv.DictReader(table.open()))
    truth = {r["beacon_id"]: float(r["offset_s"]) for r in rows}
    text = table.read_text().splitlines(keepends=True)
    for k, row in enumerate(rows, start=1):
        if row["beacon_id"] in WRONG:
            fields = text[k].split(",")
            fields[3] = f"{truth[row['beacon_id']] + WRONG[row['beacon_id']]:g}"
            text[k] = ",".join(fields)
    table.write_text("".join(text))
    return root, truth


@pytest.mark.slow
def test_the_mission_decides_the_wrong_offsets_tracks_with_them_and_a_rerun_tracks_nothing(faulted, tmp_path):
    root, truth = faulted
    out = tmp_path / "out"
    result = _batch(root, out)
    assert result.exit_code == 0, result.output
    rows = {(r["source"], r["field"]): r for r in csv.DictReader((out / "m" / "array.csv").open())}
    decided = {key for key, r in rows.items() if r["calibrated"]}
    assert decided == {(b, "offset_s") for b in WRONG}
    for source in WRONG:
        row, clock = rows[source, "offset_s"], rows[source, "clock_s"]
        assert row["outcome"] == clock["outcome"] == "contradicted"
        assert abs(float(row["estimated"]) - truth[source]) < 2 * float(row["sd"])
        # The sources' drifts are 0: the offset written is the clock over the mission.
        assert abs(float(row["calibrated"]) - truth[source]) < 2 * float(clock["sd"])
    calibrated = {r["beacon_id"]: r for r in csv.DictReader((out / "m" / "beacons-calibrated.csv").open())}
    given = {r["beacon_id"]: r for r in csv.DictReader((root / "m" / "beacons.csv").open())}
    assert {b for b in given if given[b] != calibrated[b]} == set(WRONG)
    for float_dir in sorted((out / "m").glob("sim*")):
        run = json.loads((float_dir / "run.json").read_text())
        assert Path(run["inputs"]["beacons"]["path"]).name == "beacons-calibrated.csv"
    record = json.loads((out / "m" / "array.json").read_text())
    assert record["rounds"][-1]["settled"]
    # Round 1's floats were tracked with the table as given; the last round's, within 1 sd.
    assert record["rounds"][0]["moved_sd"] is None and record["rounds"][-1]["moved_sd"] <= 1.0
    assert sorted(record["decided"]) == sorted(f"{b} {field}" for b in WRONG for field in ("clock_s", "offset_s"))
    again = _batch(root, out)
    assert again.exit_code == 0 and "0 processed, 3 skipped" in again.output, again.output
    # A float whose tracking failed in a round keeps the outputs of the table before: the
    # fit leaves it out (and says so) rather than take it as tracked with this one.
    run_file = out / "m" / "sim1" / "run.json"
    run = json.loads(run_file.read_text())
    run["inputs"]["beacons"]["sha256"] = file_digest(root / "m" / "beacons.csv")
    run_file.write_text(json.dumps(run))
    fitted = fit_mission(discover([root])[0], out, (), {}, plots=False, round_=2)
    assert fitted is not None and fitted.left_out == 1
    assert "1 float(s) left out: their outputs were tracked with another table" in round_line(fitted, 2)


@pytest.mark.slow
def test_without_the_array_fit_each_float_checks_alone(faulted, tmp_path):
    root, _ = faulted
    out = tmp_path / "out"
    (out / "m").mkdir(parents=True)
    for name in ("array.csv", "array.json", "beacons-calibrated.csv"):  # an earlier run's fit
        (out / "m" / name).write_text("earlier\n")
    result = _batch(root, out, "--no-array-fit")
    assert result.exit_code == 0, result.output
    assert not list((out / "m").glob("array*")) and not (out / "m" / "beacons-calibrated.csv").exists()
    assert (
        "an earlier run's array fit removed (array.csv, array.json, beacons-calibrated.csv)"
        in (out / "batch.log").read_text()
    )
    for float_dir in sorted((out / "m").glob("sim*")):
        run = json.loads((float_dir / "run.json").read_text())
        assert Path(run["inputs"]["beacons"]["path"]).name == "beacons.csv"
