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

    python benchmarks/mission_refit.py DIR [--rounds 2] [--from-round 2] [--workers 2] [--report docs/validation.md]

Prints, per fault set and scenario seed, the corrections written in each round (right: the
injected fault's source and field; else a false correction) and the floats failing each
accuracy target of the fault benchmark before and after each round. Round k reads the
findings of the tracks of the last table of each mission and writes its corrected copies
to DIR/seed*/missions/<set>+supported[k], their tracks to DIR/seed*/out/<set>+supported[k]
(no suffix number for round 1); `--from-round K` reads rounds before K from an earlier
run instead of tracking them again.
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


def figures(truth: pd.DataFrame, float_id: str, out: Path) -> dict[str, float]:
    """A stored track's figures against the float's truth (`robustness.position_figures`)."""
    track = pd.read_parquet(out / float_id / "track.parquet")
    track["time"] = track["time"].dt.tz_localize(None)  # stored in UTC; the truth's are naive UTC
    return position_figures(track, truth)


def round_name(name: str, round_: int) -> str:
    """The folder name of a fault set's round: the set itself (round 0, the tables as
    faulted), then `<set>+supported`, `<set>+supported2`, ..."""
    return name if round_ == 0 else f"{name}{SUFFIX}{'' if round_ == 1 else round_}"


def latest(seed_dir: Path, name: str, mission: str, before: int) -> tuple[Path, Path]:
    """A mission's latest table before round `before`: the folder of its copy (or the
    original) and the outputs of its floats tracked with it."""
    for k in range(before - 1, 0, -1):
        copy = seed_dir / "missions" / round_name(name, k) / mission
        if copy.is_dir():
            return copy, seed_dir / "out" / round_name(name, k)
    return seed_dir / "missions" / name / mission, seed_dir / "out" / name


def refit_round(seed_dir: Path, name: str, round_: int, workers: int, track: bool) -> list[dict[str, Any]]:
    """Round `round_` (from 1) of one fault set of one seed: per mission, the corrections
    its floats' outputs of the last round support, and (with `track`) its floats tracked
    again with the table so corrected; a mission without one keeps its last tracks."""
    new_missions = seed_dir / "missions" / round_name(name, round_)
    new_out = seed_dir / "out" / round_name(name, round_)
    if track:  # nothing of an earlier run of this round: a mission without a correction has no copy
        for folder in (new_missions, new_out):
            shutil.rmtree(folder, ignore_errors=True)
    corrections, tasks = [], []
    for mission in sorted(p for p in (seed_dir / "missions" / name).iterdir() if p.is_dir()):
        table, out = latest(seed_dir, name, mission.name, round_)
        chosen = mission_corrections(table, out)
        corrections += [
            {"mission": mission.name, "source": c.id, "field": c.field, "right": is_right(c, table)} for c in chosen
        ]
        if chosen:
            copy = rewritten(table, chosen, new_missions) if track else new_missions / mission.name
            tasks += [(f, new_out, ()) for f in float_files(copy)]
    if track:
        new_out.mkdir(parents=True, exist_ok=True)
        run_tasks(score_faulted, tasks, workers)
    elif any(not (new_out / f.stem / "track.parquet").exists() for f, _, _ in tasks):
        raise SystemExit(f"{new_out}: round {round_} was not tracked; run it (--from-round {round_} or lower)")
    return corrections


def refit_set(
    seed_dir: Path, name: str, rounds: int, workers: int, from_round: int
) -> tuple[pd.DataFrame, list[list[dict[str, Any]]]]:
    """One fault set of one seed, `rounds` rounds (those before `from_round` read from an
    earlier run, not tracked): each round's corrections, and per float its figures with
    correct tables (`ok_*`), faulted ones and after each round (`r1_*`, `r2_*`, ...)."""
    corrections = [refit_round(seed_dir, name, k, workers, k >= from_round) for k in range(1, rounds + 1)]
    rows = []
    for mission in sorted(p for p in (seed_dir / "missions" / name).iterdir() if p.is_dir()):
        for f in float_files(mission):
            truth, _ = read_truth(f)
            row: dict[str, Any] = {"float": f.stem}
            row |= {f"ok_{k}": v for k, v in figures(truth, f.stem, seed_dir / "out" / "correct" / "default").items()}
            row |= figures(truth, f.stem, seed_dir / "out" / name)
            for k in range(1, rounds + 1):
                _, out = latest(seed_dir, name, mission.name, k + 1)
                row |= {f"r{k}_{key}": v for key, v in figures(truth, f.stem, out).items()}
            rows.append(row)
    return pd.DataFrame(rows), corrections


def failing(table: pd.DataFrame, prefix: str = "") -> dict[str, list[str]]:
    """Per accuracy target, the floats beyond it (the `prefix`ed figures against `ok_*`)."""
    view = table[["float", *(f"ok_{k}" for k in FIGURES)]].assign(**{k: table[f"{prefix}{k}"] for k in FIGURES})
    return {target: list(view.loc[view.apply(test, axis=1), "float"]) for target, test in TARGETS.items()}


def _spent(seconds: float, args: argparse.Namespace) -> str:
    """What this run tracked, and in how long."""
    if args.from_round > args.rounds:
        return "Every round read from earlier runs of this script (none tracked in this one). "
    earlier = f"; rounds before {args.from_round} read from an earlier run" if args.from_round > 1 else ""
    return f"Rounds {args.from_round}-{args.rounds} tracked in {seconds:.0f} s with {args.workers} workers{earlier}. "


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("root", type=Path, help="a robustness.py --faults --out directory")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--rounds", type=int, default=1, help="corrections and tracking again, this many times")
    parser.add_argument(
        "--from-round", type=int, default=1, help="read the rounds before this one from an earlier run of DIR"
    )
    parser.add_argument("--report", type=Path, help="write the results into this Markdown file's mission-refit section")
    args = parser.parse_args()
    started = time.perf_counter()
    lines, summary = [], []
    for seed_dir in sorted(args.root.glob("seed*")):
        sets = sorted(p.name for p in (seed_dir / "missions").iterdir() if p.name != "correct" and SUFFIX not in p.name)
        for name in sets:
            table, corrections = refit_set(seed_dir, name, args.rounds, args.workers, args.from_round)
            stages = ["", *(f"r{k}_" for k in range(1, args.rounds + 1))]
            beyond = [failing(table, stage) for stage in stages]
            seed = seed_dir.name.removeprefix("seed")
            summary.append(
                {
                    "set": name,
                    "seed": seed,
                    "corrections (right/false) per round": ", ".join(
                        f"{sum(c['right'] for c in done)}/{sum(not c['right'] for c in done)}" for done in corrections
                    ),
                    **{t: " -> ".join(str(len(b[t])) for b in beyond) for t in TARGETS},
                    "RMSE km (median)": " -> ".join(f"{table[f'{stage}rmse_km'].median():.1f}" for stage in stages),
                }
            )
            for k, done in enumerate(corrections, 1):
                false = [f"{c['mission']} {c['source']} {c['field']}" for c in done if not c["right"]]
                if false:
                    lines.append(f"- {name}, seed {seed}, round {k}: false corrections: {'; '.join(false)}")
            print(markdown_table(pd.DataFrame(summary[-1:])), flush=True)
    frame = pd.DataFrame(summary).sort_values(["set", "seed"], kind="stable")
    body = (
        "Each faulted mission of a `robustness.py --faults ... --out DIR` run tracked again with the beacon table "
        f"its floats' findings support (`beacons-supported.csv`), {args.rounds} round(s): each round corrects, per "
        "mission, the value its floats' outputs of the last round decide, and tracks the mission's floats again "
        "with it (a mission without one keeps its tracks). "
        + _spent(time.perf_counter() - started, args)
        + "Corrections: right where they are of an injected fault. Per accuracy target, the floats beyond it "
        "against the correct tables' run: faulted tables -> after each round:\n\n"
        + markdown_table(frame)
        + ("\n\n" + "\n".join(lines) if lines else "")
    )
    print(body)
    if args.report:
        argv = ["DIR" if arg == str(args.root) else arg for arg in sys.argv]  # not this machine's folder
        write_section(args.report, "mission-refit", body, argv)


if __name__ == "__main__":
    main()
