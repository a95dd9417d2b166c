"""Wall time to track the 2-year sample float (float767) with the default settings.

Prints the time of the whole filter run per method and per window; `--profile` prints the
top functions by cumulative time (cProfile), for finding what to optimise.

    python benchmarks/speed.py [--methods exact bp] [--profile]
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import time
from pathlib import Path

from rafostrack.config import with_overrides
from rafostrack.filter import ParticleFilter, float_rng
from rafostrack.pipeline import TrackInputs, load_float

SAMPLE = Path(__file__).resolve().parents[1] / "data" / "samples" / "float767.csv"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--float-file", type=Path, default=SAMPLE)
    parser.add_argument("--methods", nargs="+", default=["exact", "bp", "unranked", "labeled"])
    parser.add_argument("--profile", action="store_true")
    args = parser.parse_args()

    loaded = load_float(TrackInputs(args.float_file))
    n_windows = len(loaded.record.windows)
    n_toas = sum(w.n_signals for w in loaded.record.windows)
    print(f"{args.float_file.name}: {n_windows} windows, {n_toas} TOAs, {len(loaded.beacons)} beacons")
    print(f"{'method':>9} {'particles':>9} {'seconds':>8} {'ms/window':>10}")
    for method in args.methods:
        config = with_overrides(loaded.config, filter={"method": method})
        pf = ParticleFilter(loaded.beacons, loaded.info, config)
        rng = float_rng(config.filter.seed, loaded.info.float_id)
        profiler = cProfile.Profile() if args.profile else None
        started = time.perf_counter()
        if profiler:
            profiler.enable()
        pf.run(loaded.record, rng)
        if profiler:
            profiler.disable()
        elapsed = time.perf_counter() - started
        print(f"{method:>9} {config.filter.particles:9d} {elapsed:8.2f} {1e3 * elapsed / n_windows:10.2f}", flush=True)
        if profiler:
            pstats.Stats(profiler).sort_stats("cumulative").print_stats(15)


if __name__ == "__main__":
    main()
