"""Generate the sample mission (simulated arrivals on the real DIMES geometry).

It lives in rafostrack/data/samples/ (package data; data/samples is a link to it).

The DIMES floats 759, 767 and 811 drift between their real launch and recovery fixes;
the 12 sound sources have their real positions, transmission slots and deployment dates;
the arrival times are simulated with `rafostrack.sim.simulate` (see its module docstring) under
the default model except `detection_range_km` (1000 km, the DIMES source range).

    python scripts/make_sample.py          # writes rafostrack/data/samples/ (also: make sample)
    python scripts/make_sample.py /tmp/m   # elsewhere
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from rafostrack.config import load_config
from rafostrack.sim.mission_writer import write_mission
from rafostrack.sim.scenarios import dimes_scenario
from rafostrack.sim.simulate import simulate_mission, summarize

DEFAULT_OUTDIR = Path(__file__).resolve().parents[1] / "rafostrack" / "data" / "samples"
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

    table = summarize(mission)
    print(f"wrote {args.outdir} (seed {args.seed})")
    print(table.to_string(index=False, float_format=lambda x: f"{x:.3f}"))
    total = sum(p.stat().st_size for p in args.outdir.rglob("*") if p.is_file())
    print(f"total size: {total / 1024:.0f} KiB")


if __name__ == "__main__":
    main()
