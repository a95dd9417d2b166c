"""The mission's array fit on stress missions whose tables carry several faults at once.

One mission of `--floats` floats per scenario seed in one array (`--geometry`, DIMES by
default; `rafostrack.sim.stress`, a generator that is not the tracker's model: eddying
drift, clock wander, multipath, outages, per-source sound speeds, clutter), written twice:
with the correct tables and with the faults `--faults` (by default four source values and
one float clock, the case a field catalogue brings: an offset 20-40 s off, another source in
the next slot, a position 20-40 km off, a drift 0.02-0.05 s/day off, and end clock offsets
left out on a share `--clock-share` of the floats). Each is tracked with `rafostrack batch`
as a user would, without the array fit (`--no-array-fit`: each float checking the tables
alone) and with it: the correct tables alone are the reference (the tracker as it was
before the array fit), the correct tables with the fit show its false findings and any
float it made worse. Prints per run and float the RMSE, p95 and confidently wrong windows
(error > 30 km with sd_km under half of it) against the truth, then per run: floats beyond
the reference (RMSE > max(5 km, 1.2x) or p95 > max(15 km, 1.2x)), the median RMSE, the confidently
wrong windows, the fixes the tracks moved by more than 50 km, and for the array fit each
injected source fault (named by the mission: `array.csv` contradicted, with the right
source and field, or for a wrong offset or drift the source's clock over the mission; its
estimate within 2 sd of the truth) and the false findings (values
contradicted that were right).

    python benchmarks/mission_array.py [--floats 24] [--days 240] [--seed 2026 ...]
                                       [--faults "KIND,... each"] [--jobs 2] [--out DIR]
                                       [--no-alone] [--report docs/validation.md] [--section NAME]

`--faults each` runs every source fault kind alone (a mission each, the same floats),
besides or instead of the set of several at once; `--no-alone` skips the faulted missions
without the fit. `--report FILE` writes each run's summary into the section `--section`
(`mission-array` by default; validation.md keeps the kinds alone in `mission-array-each`)
of that Markdown file (`benchmarks/report.py`).
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd
from report import markdown_table, write_section

from rafostrack.batch import run_batch
from rafostrack.domain import days_between
from rafostrack.mission.array_checks import CLOCK
from rafostrack.model.geodesy import local_offsets_km
from rafostrack.sim.evaluate import confidently_wrong, position_errors_km
from rafostrack.sim.faults import SOURCE_KINDS, InjectedFault, read_faults
from rafostrack.sim.stress import simulate_stress, with_faults, write_stress_mission
from rafostrack.sim.stress_config import StressConfig
from rafostrack.sim.stress_float import substream

FAULTS = "source_offset,source_slot,source_position,source_drift,end_clock_missing"
FAULT_STREAM = 77
REFERENCE = "correct alone"
TIMING_FIELDS = ("offset_s", "drift_s_per_day")


def fault_sets(text: str) -> dict[str, tuple[str, ...]]:
    """The fault sets of `--faults`: `KIND,KIND,...` (one set, several at once), `each` (every
    source kind alone), or both, separated by spaces; a kind alone named by itself, a set of
    several `several` (then `several2`, ...)."""
    sets: dict[str, tuple[str, ...]] = {}
    for word in text.split():
        for kinds in [(k,) for k in SOURCE_KINDS] if word == "each" else [tuple(word.split(","))]:
            several = sum(len(k) > 1 for k in sets.values())
            sets[kinds[0] if len(kinds) == 1 else f"several{several + 1 if several else ''}"] = kinds
    return sets


def make_missions(
    root: Path, n: int, days: int, seed: int, sets: dict[str, tuple[str, ...]], share: float, geometry: str
) -> None:
    """`root/correct` and `root/faulted-<set>` per fault set: the same floats, the tables
    correct and with each set's faults (drawn from the same stream whatever the sets)."""
    cfg = StressConfig(days=days, clutter_rate=1.5, clock_end_offset_s=(-40.0, 40.0))
    rng = np.random.default_rng([seed, 53])
    mission = simulate_stress(geometry, n, rng, cfg, prefix="f")
    write_stress_mission(mission, root / "correct" / "m")
    for name, kinds in sets.items():
        wrong = dataclasses.replace(cfg, faults=kinds, fault_float_share=share)
        write_stress_mission(with_faults(mission, wrong, substream(rng, FAULT_STREAM)), root / f"faulted-{name}" / "m")


def scores(out: Path, mission: Path) -> pd.DataFrame:
    """Per float: RMSE, p95, confidently wrong windows and the fixes moved > 50 km."""
    rows = []
    for truth_file in sorted((mission / "truth").glob("*.csv")):
        float_dir = out / "m" / truth_file.stem
        track = pd.read_parquet(float_dir / "track.parquet")
        track["time"] = track["time"].dt.tz_localize(None)
        truth = pd.read_csv(truth_file, parse_dates=["time"])
        truth["time"] = truth["time"].dt.tz_localize(None)
        err = position_errors_km(track, truth)
        checks = json.loads((float_dir / "run.json").read_text()).get("metadata_checks", [])
        moved = [c for c in checks if c["field"].endswith("_fix") and c.get("used") not in (None, c.get("given"))
                 and (c.get("supported") or 0) > 50]  # fmt: skip
        rows.append({"float": truth_file.stem, "rmse_km": float(np.sqrt(np.nanmean(err**2))),
                     "p95_km": float(np.nanpercentile(err, 95)),
                     "confident_wrong": int(confidently_wrong(err, track["sd_km"].to_numpy()).sum()),
                     "fixes_moved": len(moved)})  # fmt: skip
    return pd.DataFrame(rows).set_index("float")


def _within(fault: InjectedFault, row: dict[str, str]) -> bool:
    """Whether the mission's estimate of a faulted value lies within 2 sd of the truth."""
    if not row.get("sd"):
        return False
    sd = float(row["sd"])
    if fault.field == "position":
        lat, lon = (float(v) for v in row["estimated"].split())
        east, north = local_offsets_km(lat, lon, *fault.true)  # type: ignore[misc]
        return bool(np.hypot(east, north) < 2 * sd)
    return abs(float(row["estimated"]) - float(fault.true)) < 2 * sd  # type: ignore[arg-type]


def _clock_within(fault: InjectedFault, row: dict[str, str], start: np.datetime64) -> bool:
    """Whether the mission's clock of a source whose offset or drift is wrong lies within 2 sd
    of the true clock at its time `at`: the table's clock there plus the fault's error (an
    offset's, or a drift's times the days since the source's start)."""
    if not row.get("sd") or not row.get("at") or np.isnat(start):
        return False
    error = float(fault.true) - float(fault.written)  # type: ignore[arg-type]
    if fault.field == "drift_s_per_day":
        error *= days_between(start, np.datetime64(row["at"]))
    return abs(float(row["estimated"]) - float(row["given"]) - error) < 2 * float(row["sd"])


def array_verdict(out: Path, mission: Path) -> dict[str, object]:
    """The source faults the mission named (and estimated within 2 sd) and its false findings:
    a wrong offset or drift is named by its own value or, where the arrivals decide the
    source's clock over the mission but not how its error splits, by the clock (`clock_s`)."""
    path = out / "m" / "array.csv"
    rows = {(r["source"], r["field"]): r for r in csv.DictReader(path.open())} if path.exists() else {}
    table = pd.read_csv(mission / "beacons.csv", dtype={"beacon_id": str}).set_index("beacon_id")
    starts = pd.to_datetime(table["start"], utc=True).dt.tz_localize(None).to_numpy()
    start_of = dict(zip(table.index, starts, strict=True))
    faults = [f for f in read_faults(mission / "truth" / "faults.json") if f.file == "beacons.csv"]
    timing = [f for f in faults if f.field in TIMING_FIELDS]
    wrong = {(f.id, f.field) for f in faults} | {(f.id, CLOCK) for f in timing}

    def contradicted(key: tuple[str, str]) -> bool:
        return rows.get(key, {}).get("outcome") == "contradicted"

    named = [f for f in faults if contradicted((f.id, f.field))]
    by_clock = [f for f in timing if f not in named and contradicted((f.id, CLOCK))]
    within = [f for f in named if _within(f, rows[f.id, f.field])]
    within += [f for f in by_clock if _clock_within(f, rows[f.id, CLOCK], start_of.get(f.id, np.datetime64("NaT")))]
    false = [k for k, r in rows.items() if r["outcome"] == "contradicted" and k not in wrong]
    return {
        "source faults": len(faults),
        "named": len(named) + len(by_clock),
        "by the clock": len(by_clock),
        "within 2 sd": len(within),
        "false findings": len(false),
        "values checked": len(rows),
        "faults": "; ".join(f"{f.id} {f.field} {f.written}->{f.true}" for f in faults),
        "named ones": "; ".join([f"{f.id} {f.field}" for f in named] + [f"{f.id} {f.field} (clock)" for f in by_clock]),
        "false ones": "; ".join(map(" ".join, false)),
    }


def runs(sets: dict[str, tuple[str, ...]], alone: bool = True) -> list[tuple[str, str, dict[str, bool]]]:
    """(name, mission folder, run_batch flags) of each run: the correct tables alone (the
    reference) and with the array fit, then each fault set's alone (unless not `alone`) and
    with it."""
    found = [(REFERENCE, "correct", {"array_fit": False}), ("correct + array", "correct", {})]
    for name in sets:
        folder = f"faulted-{name}"
        found += [(f"{name} alone", folder, {"array_fit": False})] if alone else []
        found += [(f"{name} + array", folder, {})]
    return found


def beyond(table: pd.DataFrame, ok: pd.DataFrame) -> pd.Series:
    """Per float, whether it is beyond the reference: RMSE > max(5 km, 1.2x), p95 > max(15 km, 1.2x)."""
    return (table["rmse_km"] > np.maximum(5, 1.2 * ok["rmse_km"])) | (
        table["p95_km"] > np.maximum(15, 1.2 * ok["p95_km"])
    )


def rounds_of(out: Path) -> str:
    """The array fit's rounds (`array.json`): per round the values decided and how far the
    table tracked with lay from them (`moved_sd`), and whether the last settled."""
    path = out / "m" / "array.json"
    if not path.exists():
        return ""
    rounds = json.loads(path.read_text())["rounds"]
    moved = [f"{r['moved_sd']:.1f}" if r.get("moved_sd") is not None else "-" for r in rounds]
    settled = "settled" if rounds[-1]["settled"] else "not settled"
    decided = ", ".join(str(len(r["decided"])) for r in rounds)
    return f"{len(rounds)} ({decided} decided; moved {', '.join(moved)} sd; {settled})"


def _count_of(count: int, floats: pd.Index) -> str:
    """A count and, in brackets, the floats it is of."""
    return f"{count} ({', '.join(floats)})" if count else "0"


def summary(seed: int, name: str, table: pd.DataFrame, ok: pd.DataFrame, verdict: dict | None, out: Path) -> dict:
    """One run's row of the report: the floats against the reference, and the array's verdict."""
    lost, wrong = beyond(table, ok), table["confident_wrong"]
    row = {"seed": seed, "run": name,
           "floats beyond": _count_of(int(lost.sum()), table.index[lost]),
           "median RMSE km": round(float(table["rmse_km"].median()), 1),
           "conf. wrong windows": _count_of(int(wrong.sum()), table.index[wrong > 0]),
           "reference's": int(ok["confident_wrong"].sum()),
           "fixes moved > 50 km": int(table["fixes_moved"].sum())}  # fmt: skip
    if verdict is not None:
        row |= {"faults named": f"{verdict['named']}/{verdict['source faults']}",
                "within 2 sd": f"{verdict['within 2 sd']}/{verdict['named']}",
                "false findings": f"{verdict['false findings']}/{verdict['values checked']}",
                "rounds": rounds_of(out)}  # fmt: skip
    return row


def _out_of(root: Path, name: str) -> Path:
    """The batch output folder of the run `name`."""
    return root / "out" / name.replace(" ", "_").replace("+", "and")


def run(root: Path, seed: int, args: argparse.Namespace) -> list[dict]:
    """Every run of one scenario seed (`runs`), printed; the report's rows (`summary`)."""
    sets = fault_sets(args.faults)
    make_missions(root, args.floats, args.days, seed, sets, args.clock_share, args.geometry)
    tables, verdicts, seconds = {}, {}, {}
    for name, mission, flags in runs(sets, not args.no_alone):
        out = _out_of(root, name)
        started = time.perf_counter()
        run_batch([root / mission], out, jobs=args.jobs, plots=False, stream=open("/dev/null", "w"), **flags)
        seconds[name] = time.perf_counter() - started
        tables[name] = scores(out, root / mission / "m")
        print(f"seed {seed}, {name}: {seconds[name]:.0f} s", flush=True)
        if flags.get("array_fit", True):
            verdicts[name] = array_verdict(out, root / mission / "m")
            print(f"  array: {verdicts[name]}", flush=True)
    ok = tables[REFERENCE]
    print(pd.concat(tables, axis=1).round(1).to_string())
    rows = []
    for name, table in tables.items():
        rows.append(summary(seed, name, table, ok, verdicts.get(name), _out_of(root, name)))
        rows[-1]["seconds"] = round(seconds[name])
        print(", ".join(f"{k} {v}" for k, v in rows[-1].items()), flush=True)
    return rows


REPORT_HEAD = """Per scenario seed, each run of one mission tracked with `rafostrack batch`: the correct
tables without the array fit (the reference) and with it, then each fault set (one source
fault kind alone, or several at once) without the fit and with it (`benchmarks/mission_array.py`,
module docstring). Floats beyond: RMSE > max(5 km, 1.2x) or p95 > max(15 km, 1.2x) the
reference's, same float. Confidently wrong windows: error > 30 km with sd_km under half of
it (the floats having them in brackets); the reference's beside. Faults named:
contradicted in `array.csv` with the right source and field (or by the source's clock over
the mission); within 2 sd: the named estimate against the truth. False findings:
contradicted values that were right, of the values checked. Rounds: the array's rounds,
the values each decided, how far the table each was tracked with lay from its decisions
(in their sds), and whether the last settled. Seconds: the whole run on two worker
processes."""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--floats", type=int, default=24)
    parser.add_argument("--days", type=int, default=240)
    parser.add_argument("--seed", type=int, nargs="+", default=[2026])
    parser.add_argument(
        "--faults",
        default=FAULTS,
        help="fault sets, space-separated: KIND,KIND,... (several at once) or each (every source kind alone)",
    )
    parser.add_argument("--clock-share", type=float, default=0.1, help="share of floats whose end clock is left out")
    parser.add_argument("--geometry", default="dimes")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--out", type=Path, help="keep the missions and outputs here")
    parser.add_argument("--no-alone", action="store_true", help="skip the faulted missions without the array fit")
    parser.add_argument("--report", type=Path, help="write the runs' summary into this Markdown file's section")
    parser.add_argument(
        "--section", default="mission-array", help="the report's section (e.g. mission-array-each for --faults each)"
    )
    args = parser.parse_args()
    print(" ".join(sys.argv), flush=True)
    rows: list[dict] = []
    for seed in args.seed:
        if args.out is not None:
            rows += run(args.out / str(seed), seed, args)
        else:
            with tempfile.TemporaryDirectory() as tmp:
                rows += run(Path(tmp), seed, args)
        if args.report is not None:  # after each seed: a long run stopped keeps the seeds done
            frame = pd.DataFrame(rows)
            frame = frame[[c for c in frame if c != "seconds"] + ["seconds"]]
            table = markdown_table(frame, {"median RMSE km": "{:.1f}".format})
            write_section(args.report, args.section, f"{REPORT_HEAD}\n\n{table}")


if __name__ == "__main__":
    main()
