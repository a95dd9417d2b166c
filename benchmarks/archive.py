"""A DIMES-size archive through `rafostrack batch`: floats per minute and peak memory.

Simulates the DIMES experiment as an archive: the 140 real launch/recovery pairs
(`benchmarks/data/dimes_all_floats.csv`, from the public DIMES float table) and the 12 real sound
sources, each float drifting from its launch to its recovery fix (integrated OU eddies
around the mean velocity, `rafostrack.sim.simulate`), arrival times simulated along the drift
with the default measurement model (clutter 1 per window, multipath, echoes). The mission
directory holds no `rafostrack.toml`, so the floats are tracked with the default settings,
as a user's archive would be. Then runs the installed `rafostrack batch` on it as cron
would (a fresh process, no plots), with `--jobs` = all cores, and, with `--dask`, again on
a Dask LocalCluster of as many single-threaded workers (`--scheduler`). Prints wall time,
floats per minute, window-days per second, and the peak resident memory of the largest
process (the batch process and its workers: `ru_maxrss` of the children; for Dask, of the
workers as reported by the scheduler), and the mission's rounds as its log has them.

`--offset-fault S` writes the table of the source the most floats hear S seconds off: the
mission decides it after the first round and tracks again the floats hearing it (the whole
mission method, two rounds and the array fits, as a faulted catalogue costs it).

    python benchmarks/archive.py [--floats 140] [--jobs N] [--offset-fault S] [--dask] [--keep DIR]

`--floats K` takes the first K floats (a quick look; floats/min is per float of ~2 years).
"""

from __future__ import annotations

import argparse
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from rafostrack.batch import default_jobs
from rafostrack.config import load_config
from rafostrack.domain import FloatInfo
from rafostrack.sim.mission_writer import write_mission
from rafostrack.sim.scenarios import dimes_scenario
from rafostrack.sim.simulate import SimulatedMission, simulate_mission

FLOATS_CSV = Path(__file__).resolve().parent / "data" / "dimes_all_floats.csv"
SEED = 2026  # the simulation's default seed


def dimes_archive_floats(n_floats: int | None = None) -> list[FloatInfo]:
    """The real DIMES floats (launch and recovery fixes, dates, clock offsets)."""
    table = pd.read_csv(FLOATS_CSV, dtype={"float_id": str})
    if n_floats is not None:
        table = table.head(n_floats)

    def day(text: str) -> np.datetime64:
        return pd.Timestamp(text).tz_convert(None).floor("D").to_datetime64().astype("datetime64[ns]")

    return [
        FloatInfo(
            float_id=f"float{row.float_id}",
            launch_time=day(row.launch_time),
            launch_lat=float(row.launch_lat),
            launch_lon=float(row.launch_lon),
            end_time=day(row.end_time),
            end_lat=float(row.end_lat),
            end_lon=float(row.end_lon),
            clock_offset_start_s=float(row.clock_offset_start_s),
            clock_offset_end_s=float(row.clock_offset_end_s),
            window_s=4200.0,
            max_signals=4,
        )
        for row in table.itertuples()
    ]


def write_archive(mission: Path, n_floats: int | None, seed: int = SEED) -> SimulatedMission:
    """Simulate the first `n_floats` DIMES floats (all: None) into the mission directory
    `mission`, without a rafostrack.toml (the default settings, as for a user's archive)."""
    floats = dimes_archive_floats(n_floats)
    simulated = simulate_mission(dimes_scenario()[0], floats, load_config().model, np.random.default_rng(seed))
    write_mission(simulated, mission)
    (mission / "rafostrack.toml").unlink()
    return simulated


def fault_offset(mission: Path, seconds: float) -> str:
    """Write the offset of the source most heard (by the arrival files' true labels) in
    `mission`'s beacons.csv `seconds` off; returns its id."""
    heard = pd.concat([pd.read_csv(f, usecols=["beacon_id"]) for f in sorted(mission.glob("*.csv"))
                       if f.name not in ("beacons.csv", "floats.csv")])  # fmt: skip
    source = str(heard["beacon_id"].value_counts().idxmax())
    table = pd.read_csv(mission / "beacons.csv", dtype=str, keep_default_na=False)
    row = table["beacon_id"] == source
    table.loc[row, "offset_s"] = f"{float(table.loc[row, 'offset_s'].iloc[0]) + seconds:g}"
    table.to_csv(mission / "beacons.csv", index=False)
    return source


def _rounds(out: Path) -> list[str]:
    """The batch log's first line and its mission's array-fit lines (one per round), with
    their times: each round's wall time is between them."""
    lines = (out / "batch.log").read_text().splitlines()
    return lines[:1] + [line for line in lines if "array fit, round" in line]


def _rafostrack() -> str:
    exe = shutil.which("rafostrack", path=str(Path(sys.executable).parent))
    if exe is None:
        raise SystemExit("no rafostrack entry point beside this Python: pip install -e . first")
    return exe


def _run(command: list[str]) -> float:
    started = time.perf_counter()
    proc = subprocess.run(command, capture_output=True, text=True, check=False)
    elapsed = time.perf_counter() - started
    if proc.returncode != 0:
        raise SystemExit(f"batch failed ({proc.returncode}):\n{proc.stdout[-2000:]}{proc.stderr[-2000:]}")
    return elapsed


def _report(label: str, elapsed: float, n_floats: int, n_windows: int, peak_mb: float) -> None:
    print(
        f"{label:>18} {elapsed:8.1f} {n_floats / elapsed * 60:10.2f} {n_windows / elapsed:12.1f} {peak_mb:12.0f}",
        flush=True,
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--floats", type=int, default=None, help="the first K floats (default: all 140)")
    parser.add_argument("--jobs", type=int, default=default_jobs())
    parser.add_argument("--seed", type=int, default=SEED)
    parser.add_argument("--offset-fault", type=float, default=0.0, help="the most heard source's offset so far off (s)")
    parser.add_argument("--dask", action="store_true", help="also run on a Dask LocalCluster")
    parser.add_argument("--keep", type=Path, help="write the archive and outputs here instead of a temporary dir")
    args = parser.parse_args()

    root = args.keep or Path(tempfile.mkdtemp(prefix="rafostrack-archive-"))
    try:
        mission = root / "archive" / "dimes"
        started = time.perf_counter()
        simulated = write_archive(mission, args.floats, args.seed)
        floats = simulated.floats
        n_windows = sum(len(f.record.windows) for f in floats)
        print(
            f"archive: {len(floats)} DIMES floats, {len(simulated.beacons)} sources, {n_windows} windows "
            f"({n_windows / len(floats):.0f} per float), simulated in {time.perf_counter() - started:.0f} s; "
            f"{args.jobs} job(s) on {default_jobs()} core(s)"
        )
        if args.offset_fault:
            print(f"tables: {fault_offset(mission, args.offset_fault)}'s offset written {args.offset_fault:g} s off")
        print(f"{'run':>18} {'wall s':>8} {'floats/min':>10} {'windows/s':>12} {'peak MB':>12}")
        command = [_rafostrack(), "batch", str(mission.parent), "--no-plots", "--jobs", str(args.jobs)]
        elapsed = _run([*command, "--out", str(root / "out-local")])
        peak_mb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
        _report(f"local --jobs {args.jobs}", elapsed, len(floats), n_windows, peak_mb)
        print("\n".join(_rounds(root / "out-local")))
        if args.dask:
            from dask.distributed import LocalCluster

            with LocalCluster(n_workers=args.jobs, threads_per_worker=1, processes=True) as cluster:
                client = cluster.get_client()
                elapsed = _run([*command, "--out", str(root / "out-dask"), "--scheduler", cluster.scheduler_address])
                rss = client.run(lambda: resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
                _report(f"dask {args.jobs} workers", elapsed, len(floats), n_windows, max(rss.values()) / 1024)
    finally:
        if args.keep is None:
            shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    main()
