"""Wall time to track the 2-year sample float (float767) with the default method.

Prints, per method and particle count, the time of the whole method (all its passes:
the robust pass, calibration, the calibrated passes), split into filter, smoother (backward
pass plus smoothed labels and summaries) and calibration (the Kalman fit and association
EM), with the track's RMSE against the sample's truth, the labels right and the median ESS
of the last pass; `--profile` prints the top functions by cumulative time (cProfile), for
finding what to optimise. Run on one core (`OMP_NUM_THREADS=1 taskset -c 0`) for figures
that do not depend on what else runs.

    python benchmarks/speed.py [--methods exact bp] [--particles 1000 10000] [--config FILE] [--profile]
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import time
from pathlib import Path

import numpy as np
import pandas as pd

from rafostrack.config import method_overrides, with_overrides
from rafostrack.evaluate import association_accuracy, rmse_km
from rafostrack.method import track_record
from rafostrack.pipeline import TrackInputs, load_float

SAMPLE = Path(__file__).resolve().parents[1] / "data" / "samples" / "float767.csv"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--float-file", type=Path, default=SAMPLE)
    parser.add_argument("--methods", nargs="+", default=["exact", "bp", "unranked", "labeled"])
    parser.add_argument("--particles", type=int, nargs="+", default=[1000, 10000])
    parser.add_argument("--config", type=Path, action="append", default=[], help="an extra config layer")
    parser.add_argument("--profile", action="store_true")
    args = parser.parse_args()

    loaded = load_float(TrackInputs(args.float_file, config_files=tuple(args.config)))
    n_windows = len(loaded.record.windows)
    n_toas = sum(w.n_signals for w in loaded.record.windows)
    print(f"{args.float_file.name}: {n_windows} windows, {n_toas} TOAs, {len(loaded.beacons)} beacons")
    truth = pd.read_csv(args.float_file.parent / "truth" / args.float_file.name, parse_dates=["time"])
    truth["time"] = truth["time"].dt.tz_localize(None)
    print(
        f"{'method':>9} {'particles':>9} {'total_s':>8} {'filter_s':>9} {'smoother_s':>10} {'calib_s':>8} "
        f"{'rmse_km':>8} {'labels':>7} {'ess/N':>6}"
    )
    for method in args.methods:
        for particles in args.particles:
            config = with_overrides(loaded.config, filter={**method_overrides(method), "particles": particles})
            profiler = cProfile.Profile() if args.profile else None
            started = time.perf_counter()
            if profiler:
                profiler.enable()
            out = track_record(loaded.beacons, loaded.info, config, loaded.record, explicit=loaded.explicit)
            if profiler:
                profiler.disable()
            elapsed = time.perf_counter() - started
            print(
                f"{method:>9} {particles:9d} {elapsed:8.2f} {out.filter_s:9.2f} {out.smoother_s:10.2f} "
                f"{out.calibrate_s:8.2f} {rmse_km(out.track, truth):8.2f} "
                f"{association_accuracy(out.labels, loaded.record):7.2%} "
                f"{np.median(out.filter_ess) / particles:6.2f}",
                flush=True,
            )
            if profiler:
                pstats.Stats(profiler).sort_stats("cumulative").print_stats(15)


if __name__ == "__main__":
    main()
