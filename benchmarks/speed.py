"""Wall time to track the 2-year sample float (float767) with the default settings.

Prints, per method, the filter's time (in total and per window) and the smoother's (the
backward pass plus the smoothed labels) and their ratio; `--profile` prints the top
functions by cumulative time (cProfile), for finding what to optimise.

    python benchmarks/speed.py [--methods exact bp] [--profile]
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import time
from pathlib import Path

from rafostrack.config import method_overrides, with_overrides
from rafostrack.method import track_record
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
    print(f"{'method':>9} {'particles':>9} {'filter_s':>9} {'ms/window':>10} {'smoother_s':>10} {'ratio':>6}")
    for method in args.methods:
        config = with_overrides(loaded.config, filter=method_overrides(method))
        profiler = cProfile.Profile() if args.profile else None
        started = time.perf_counter()
        if profiler:
            profiler.enable()
        out = track_record(loaded.beacons, loaded.info, config, loaded.record)
        if profiler:
            profiler.disable()
        elapsed = time.perf_counter() - started
        print(
            f"{method:>9} {config.filter.particles:9d} {out.filter_s:9.2f} {1e3 * out.filter_s / n_windows:10.2f} "
            f"{out.smoother_s:10.2f} {out.smoother_s / out.filter_s:6.2f}   (total {elapsed:.2f} s)",
            flush=True,
        )
        if profiler:
            pstats.Stats(profiler).sort_stats("cumulative").print_stats(15)


if __name__ == "__main__":
    main()
