"""What tracking again with the beacon table a mission's floats support would buy: the
faulted missions of a robustness run tracked again with their `beacons-supported.csv`.

`rafostrack batch` writes, per mission, the beacon table with the values its floats'
arrivals decide replaced (`batch.corrections`) and leaves it to the user to track with.
This measures what that second round gives, on the outputs of
`benchmarks/robustness.py --faults ... --out DIR`: per fault set and mission, the table
the mission's findings support (from the floats' run.json, as the batch reads them), the
floats of each mission whose table changed tracked again with it (as
`robustness.score_faulted` tracks), and each float's figures against the correct tables'
run, before and after.

    python benchmarks/mission_refit.py DIR [--workers 2] [--report docs/validation.md]

Prints, per fault set and scenario seed, the corrections written (right: the injected
fault's source and field; else a false correction) and the floats failing each accuracy
target of the fault benchmark before and after; the tracks of the second round go to
DIR/seed*/out/<set>+supported.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import time
from pathlib import Path
from typing import Any

import pandas as pd
from report import markdown_table, write_section
from robustness import (
    COVERAGE_RANGE,
    as_contradicted,
    position_figures,
    read_truth,
    run_tasks,
    score_faulted,
)

from rafostrack.batch.corrections import supported_table, to_correct
from rafostrack.batch.findings import Finding, mission_findings, parse_checks
from rafostrack.sim.faults import names, read_faults

SUFFIX = "+supported"
FIGURES = ("rmse_km", "p95_km", "cover95", "confident_wrong")
TARGETS = {  # the fault benchmark's accuracy targets (robustness.fault_targets), per float
    "p95": lambda r: r["p95_km"] > max(15.0, 1.2 * r["ok_p95_km"]),
    "rmse": lambda r: r["rmse_km"] > max(5.0, 1.2 * r["ok_rmse_km"]),
    "coverage": lambda r: _inside(r["ok_cover95"]) and not _inside(r["cover95"]),
    "confident_wrong": lambda r: r["confident_wrong"] > r["ok_confident_wrong"],
}


def _inside(cover: float) -> bool:
    return COVERAGE_RANGE[0] <= cover <= COVERAGE_RANGE[1]


def float_files(mission: Path) -> list[Path]:
    return sorted(f for f in mission.glob("*.csv") if f.name not in ("beacons.csv", "floats.csv"))


def mission_corrections(mission: Path, out: Path) -> list[Finding]:
    """The findings of a mission's floats (their run.json in `out`) that its supported table writes."""
    checks = []
    for f in float_files(mission):
        run = out / f.stem / "run.json"
        if run.exists():
            checks += parse_checks(json.loads(run.read_text()), f.stem)
    return to_correct(mission_findings(mission.name, checks))


def rewritten(mission: Path, corrections: list[Finding], to: Path) -> Path:
    """A copy of `mission` under `to` with its beacons.csv as its floats support."""
    copy = to / mission.name
    if copy.exists():
        shutil.rmtree(copy)
    shutil.copytree(mission, copy, ignore=shutil.ignore_patterns("beacons.csv"))
    with open(mission / "beacons.csv", encoding="utf-8", newline="") as table:
        (copy / "beacons.csv").write_text(supported_table(table.read(), corrections), encoding="utf-8")
    return copy


def is_right(correction: Finding, mission: Path) -> bool:
    """Whether a correction is of an injected fault: it names the fault as a float's check
    would (`faults.names`: the same source, and its field or an alternative of it, such as
    an offset written for a displaced source whose position the floats could not fix)."""
    entry = as_contradicted(correction)
    return any(names(entry, fault) for fault in read_faults(mission / "truth" / "faults.json"))


def figures(float_file: Path, out: Path) -> dict[str, float]:
    """A stored track's figures against the float's truth (`robustness.position_figures`)."""
    truth, _ = read_truth(float_file)
    track = pd.read_parquet(out / float_file.stem / "track.parquet")
    track["time"] = track["time"].dt.tz_localize(None)  # stored in UTC; the truth's are naive UTC
    return position_figures(track, truth)


def refit_set(seed_dir: Path, name: str, workers: int) -> tuple[pd.DataFrame, list[dict[str, Any]]]:
    """One fault set of one seed: the corrections, the floats tracked again, and per float
    its figures with correct tables (`ok_*`), faulted ones and the supported ones (`new_*`)."""
    missions_dir, out = seed_dir / "missions" / name, seed_dir / "out" / name
    new_missions, new_out = seed_dir / "missions" / f"{name}{SUFFIX}", seed_dir / "out" / f"{name}{SUFFIX}"
    new_out.mkdir(parents=True, exist_ok=True)
    corrections, tasks, refitted = [], [], {}
    for mission in sorted(p for p in missions_dir.iterdir() if p.is_dir()):
        chosen = mission_corrections(mission, out)
        corrections += [
            {"mission": mission.name, "source": c.id, "field": c.field, "right": is_right(c, mission)} for c in chosen
        ]
        if chosen:
            copy = rewritten(mission, chosen, new_missions)
            tasks += [(f, new_out, ()) for f in float_files(copy)]
            refitted.update({f.stem: copy for f in float_files(copy)})
    run_tasks(score_faulted, tasks, workers)
    rows = []
    for mission in sorted(p for p in missions_dir.iterdir() if p.is_dir()):
        for f in float_files(mission):
            row = {"float": f.stem, "refitted": f.stem in refitted}
            row |= {f"ok_{k}": v for k, v in figures(f, seed_dir / "out" / "correct" / "default").items()}
            before = figures(f, out)
            after = figures(refitted[f.stem] / f.name, new_out) if f.stem in refitted else before
            row |= before
            row |= {f"new_{k}": v for k, v in after.items()}
            rows.append(row)
    return pd.DataFrame(rows), corrections


def failing(table: pd.DataFrame, prefix: str = "") -> dict[str, list[str]]:
    """Per accuracy target, the floats beyond it (the `prefix`ed figures against `ok_*`)."""
    view = table[["float", *(f"ok_{k}" for k in FIGURES)]].assign(**{k: table[f"{prefix}{k}"] for k in FIGURES})
    return {target: list(view.loc[view.apply(test, axis=1), "float"]) for target, test in TARGETS.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("root", type=Path, help="a robustness.py --faults --out directory")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--report", type=Path, help="write the results into this Markdown file's mission-refit section")
    args = parser.parse_args()
    started = time.perf_counter()
    lines, summary = [], []
    for seed_dir in sorted(args.root.glob("seed*")):
        sets = sorted(p.name for p in (seed_dir / "missions").iterdir() if p.name != "correct" and SUFFIX not in p.name)
        for name in sets:
            table, corrections = refit_set(seed_dir, name, args.workers)
            before, after = failing(table), failing(table, "new_")
            right = sum(c["right"] for c in corrections)
            summary.append(
                {
                    "set": name,
                    "seed": seed_dir.name.removeprefix("seed"),
                    "corrections": f"{right} right, {len(corrections) - right} false",
                    "floats tracked again": int(table["refitted"].sum()),
                    **{t: f"{len(before[t])} -> {len(after[t])}" for t in TARGETS},
                    "RMSE km (median)": f"{table['rmse_km'].median():.1f} -> {table['new_rmse_km'].median():.1f}",
                }
            )
            false = [f"{c['mission']} {c['source']} {c['field']}" for c in corrections if not c["right"]]
            if false:
                lines.append(f"- {name}, seed {summary[-1]['seed']}: false corrections: {'; '.join(false)}")
            print(markdown_table(pd.DataFrame(summary[-1:])), flush=True)
    frame = pd.DataFrame(summary).sort_values(["set", "seed"], kind="stable")
    body = (
        "Each faulted mission of a `robustness.py --faults ... --out DIR` run tracked again with the beacon table "
        f"its floats' findings support (`beacons-supported.csv`), in {time.perf_counter() - started:.0f} s with "
        f"{args.workers} workers. "
        "Corrections: right where they are of an injected fault. Per accuracy target, the floats beyond it "
        "against the correct tables' run, faulted tables -> supported tables:\n\n"
        + markdown_table(frame)
        + ("\n\n" + "\n".join(lines) if lines else "")
    )
    print(body)
    if args.report:
        argv = ["DIR" if arg == str(args.root) else arg for arg in sys.argv]  # not this machine's folder
        write_section(args.report, "mission-refit", body, argv)


if __name__ == "__main__":
    main()
