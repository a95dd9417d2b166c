"""Wall time of `rafostrack batch` on a simulated 24-float mission, with --jobs 1 and --jobs 2.

Simulates the synthetic scenario (24 floats, 60 days, seed 0) into a temporary directory,
runs the installed `rafostrack batch` with each --jobs value as a fresh process, as cron
would (every run after the first with --force, so all floats are tracked every time; no
plots), and prints
wall times (start-up included), the speed-up over the first and whether the Parquet outputs
are byte-identical across runs.

    python benchmarks/batch.py [--floats 24] [--days 60] [--particles N] [--jobs 1 2] [--plots]
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from rafostrack.batch import default_jobs
from rafostrack.config import load_config
from rafostrack.sim.mission_writer import write_mission
from rafostrack.sim.scenarios import synthetic_scenario
from rafostrack.sim.simulate import simulate_mission


def _rafostrack() -> list[str]:
    """The installed `rafostrack` entry point beside this Python, as cron runs it."""
    exe = shutil.which("rafostrack", path=str(Path(sys.executable).parent))
    if exe is None:
        raise SystemExit("no rafostrack entry point beside this Python: pip install -e . first")
    return [exe]


def _parquet(out: Path) -> dict[str, bytes]:
    return {str(p.relative_to(out)): p.read_bytes() for p in sorted(out.rglob("*.parquet"))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--floats", type=int, default=24)
    parser.add_argument("--days", type=int, default=60)
    parser.add_argument("--particles", type=int, help="[filter] particles (default: the config's)")
    parser.add_argument("--jobs", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--plots", action="store_true", help="also draw the PNG plots")
    args = parser.parse_args()

    with tempfile.TemporaryDirectory(prefix="rafostrack-bench-") as tmp:
        mission = Path(tmp) / "missions" / "sim24"
        rng = np.random.default_rng(0)
        beacons, floats = synthetic_scenario(days=args.days, n_floats=args.floats, rng=rng)
        overrides = {"filter": {"particles": args.particles}} if args.particles else None
        write_mission(simulate_mission(beacons, floats, load_config().model, rng), mission, overrides)
        particles = args.particles or load_config([mission / "rafostrack.toml"]).filter.particles
        print(
            f"mission: {args.floats} floats x {args.days} days, {particles} particles, "
            f"plots {'on' if args.plots else 'off'}; {default_jobs()} core(s) available"
        )
        print(f"{'jobs':>4} {'wall s':>8} {'s/float':>8} {'speed-up':>9}  outputs")
        out = Path(tmp) / "out"
        first_time = reference = None
        for i, jobs in enumerate(args.jobs):
            command = [*_rafostrack(), "batch", str(mission.parent), "--out", str(out), "--jobs", str(jobs)]
            command += ["--force"] * (i > 0) + ["--no-plots"] * (not args.plots)
            started = time.perf_counter()
            proc = subprocess.run(command, capture_output=True, text=True, check=False)
            elapsed = time.perf_counter() - started
            if proc.returncode != 0:
                raise SystemExit(f"batch failed ({proc.returncode}):\n{proc.stdout}{proc.stderr}")
            outputs = _parquet(out)
            first_time = first_time or elapsed
            reference = reference or outputs
            same = "reference" if i == 0 else ("identical" if outputs == reference else "DIFFERENT")
            print(
                f"{jobs:>4} {elapsed:8.1f} {elapsed / args.floats:8.2f} {first_time / elapsed:8.2f}x  {same}",
                flush=True,
            )


if __name__ == "__main__":
    main()
