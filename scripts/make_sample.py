"""Generate the sample mission (simulated arrivals on the real DIMES geometry).

It lives in data/samples/ (what the README's commands use and a user copies); the package
carries a copy, rafostrack/data/samples/ (`rafostrack.sim.scenarios.sample_mission_dir`),
which this script refreshes when it writes data/samples and a test holds equal to it.

The DIMES floats 759, 767 and 811 drift between their real launch and recovery fixes;
the 12 sound sources have their real positions, transmission slots and deployment dates;
the arrival times are simulated with `rafostrack.sim.simulate` (see its module docstring) under
the default model except `detection_range_km` (1000 km, the DIMES source range).

    python scripts/make_sample.py          # writes data/samples/ and its package copy (also: make sample)
    python scripts/make_sample.py /tmp/m   # elsewhere
"""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

import numpy as np

from rafostrack.config import load_config
from rafostrack.sim.mission_writer import write_mission
from rafostrack.sim.scenarios import dimes_scenario
from rafostrack.sim.simulate import simulate_mission, summarize

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_OUTDIR = ROOT / "data" / "samples"
PACKAGE_COPY = ROOT / "rafostrack" / "data" / "samples"  # the package data: a copy of DEFAULT_OUTDIR
SEED = 20090123
FLOATS = ("759", "767", "811")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "outdir", type=Path, nargs="?", default=DEFAULT_OUTDIR, help="mission directory to write (default data/samples)"
    )
    parser.add_argument("--seed", type=int, default=SEED, help=f"random seed (default {SEED})")
    parser.add_argument("--detection-range-km", type=float, default=1000.0, help="source range at which Pd halves (km)")
    args = parser.parse_args(argv)

    # The sample's model, pinned: no multipath and no echoes (the defaults of the config may
    # change; the bundled sample must stay reproducible).
    overrides = {"detection_range_km": args.detection_range_km, "multipath_fraction": 0.0, "echo_fraction": 0.0}
    model = load_config(overrides={"model": overrides}).model
    beacons, floats = dimes_scenario(FLOATS)
    mission = simulate_mission(beacons, floats, model, np.random.default_rng(args.seed))
    write_mission(mission, args.outdir)
    if args.outdir.resolve() == DEFAULT_OUTDIR:
        shutil.rmtree(PACKAGE_COPY, ignore_errors=True)
        shutil.copytree(DEFAULT_OUTDIR, PACKAGE_COPY)
        print(f"copied to {PACKAGE_COPY} (the package data)")

    table = summarize(mission)
    print(f"wrote {args.outdir} (seed {args.seed})")
    print(table.to_string(index=False, float_format=lambda x: f"{x:.3f}"))
    total = sum(p.stat().st_size for p in args.outdir.rglob("*") if p.is_file())
    print(f"total size: {total / 1024:.0f} KiB")


if __name__ == "__main__":
    main()
