"""What another `[checks] z_score` would have named: the metadata checks of a faulted
robustness run judged again, without tracking again.

A check's outcome is a function of the correction the arrivals support, its sd, the
field's tolerance and the z-score (`metadata_checks.outcome_of`), all in run.json, so the
faults a lower or higher z-score names, and the false alarms it raises, can be counted on
the outputs of `benchmarks/robustness.py --faults ... --out DIR`. The tracks are not
redone: a value contradicted only at the new z-score would also have been replaced in the
track, which this does not show.

    python benchmarks/rejudge_checks.py DIR [--z 5 4 3.5 3]

Each z-score judges every field, the launch fix too (whose run used `launch_z_score`).

Prints, per field, the injected faults (those the float's arrivals show) named and the
floats with a false alarm (a contradicted value that is no injected fault), on the
faulted runs and on the correct tables' runs, at each z-score.
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from pathlib import Path
from typing import Any

import pandas as pd
from robustness import float_faults, observable_faults

from rafostrack.calibrate.metadata_checks import CONTRADICTED, TOLERANCE_SETTING, outcome_of
from rafostrack.sim.faults import false_alarms, names


def rejudged(check: dict[str, Any], settings: dict[str, Any], z: float) -> dict[str, Any]:
    """`check` with its outcome judged at `z` (unchanged where it has no numeric given,
    supported value and sd, or its field no tolerance)."""
    given, supported, sd = check.get("given"), check.get("supported"), check.get("sd")
    key = TOLERANCE_SETTING.get(str(check.get("field")))  # a shift (fix, position): given 0, the distance
    numbers = all(isinstance(v, int | float) and not isinstance(v, bool) for v in (given, supported, sd))
    if key is None or not numbers or not sd or check.get("outcome") not in (CONTRADICTED, "consistent", "undetermined"):
        return check
    return {**check, "outcome": outcome_of(float(supported) - float(given), float(sd), float(settings[key]), z)}


def float_runs(root: Path) -> list[tuple[str, Path, Path | None]]:
    """(fault set, run.json, float file) of every float of every seed; the correct tables'
    runs have no faults to read (their float file is None)."""
    runs = []
    for seed in sorted(root.glob("seed*")):
        for run_json in sorted((seed / "out" / "correct" / "default").glob("*/run.json")):
            runs.append(("correct", run_json, None))
        for fault_set in sorted(p for p in (seed / "out").iterdir() if p.is_dir() and p.name != "correct"):
            for run_json in sorted(fault_set.glob("*/run.json")):
                found = list((seed / "missions" / fault_set.name).glob(f"*/{run_json.parent.name}.csv"))
                runs.append((fault_set.name, run_json, found[0] if found else None))
    return runs


def tally(root: Path, z_scores: list[float]) -> pd.DataFrame:
    """Per z-score and field: faults shown and named, floats checked and with a false alarm,
    on the faulted runs and on the correct tables'."""
    counts: dict[tuple[float, str, str], int] = defaultdict(int)
    for fault_set, run_json, float_file in float_runs(root):
        run = json.loads(run_json.read_text())
        settings, checks = run["config"]["checks"], run.get("metadata_checks", [])
        mine = float_faults(float_file) if float_file is not None else []
        shown = observable_faults(float_file, mine) if float_file is not None else []
        where = "correct" if fault_set == "correct" else "faulted"
        for z in z_scores:
            judged = [rejudged(c, settings, z) for c in checks]
            for fault in shown:
                counts[(z, fault.field, "faults")] += 1
                counts[(z, fault.field, "named")] += any(names(c, fault) for c in judged)
            for field in {str(c.get("field")) for c in judged}:
                counts[(z, field, f"floats_{where}")] += 1
                alarms = false_alarms(mine, [c for c in judged if c.get("field") == field])
                counts[(z, field, f"false_alarm_floats_{where}")] += bool(alarms)
    table = pd.Series(counts).unstack(fill_value=0).reset_index()
    return table.rename(columns={"level_0": "z_score", "level_1": "field"})


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("root", type=Path, help="a `robustness.py --faults ... --out` directory")
    parser.add_argument("--z", type=float, nargs="+", default=[5.0, 4.0, 3.5, 3.0])
    args = parser.parse_args()
    table = tally(args.root, args.z)
    columns = ["z_score", "field", "faults", "named", "floats_faulted", "false_alarm_floats_faulted",
               "floats_correct", "false_alarm_floats_correct"]  # fmt: skip
    print(table.reindex(columns=columns, fill_value=0).to_string(index=False))


if __name__ == "__main__":
    main()
