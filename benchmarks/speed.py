"""Wall time to track the 2-year sample float (float767) with the default method.

`--archive-float` also times a float as `benchmarks/archive.py` simulates the DIMES archive
(the first of the 140 real launch/recovery pairs, the default measurement model: clutter,
multipath and echoes; tracked with the default settings), whose cost per float is what a
batch over an archive pays. Prints, per float, method and particle count, the time of the
whole method (all its passes: the robust pass, calibration, the calibrated passes), split
into filter, smoother (backward pass plus smoothed labels and summaries) and calibration
(the Kalman fit and association EM), with the track's RMSE against the float's truth, the
labels right and the median ESS of the last pass; `--profile` then prints, per pass and
calibration, the seconds of each stage of the method (motion, ranges, association,
smoother, ...: `stages.py`), for finding what to optimise, on one kernel thread (all the
work in this process: work forked beside it, `rafostrack.run.forked`, would escape the
stages' timers). Run on one core (`OMP_NUM_THREADS=1 taskset -c 0`) for figures that do not
depend on what else runs.

    python benchmarks/speed.py [--methods exact bp] [--particles 1000 10000] [--config FILE] [--profile]
                               [--archive-float] [--report docs/validation.md]

`--report FILE` also writes the table (and the stage tables, with `--profile`) into the
`speed` section of that Markdown file (`benchmarks/report.py`). The compiled kernels use
numba's threads (`NUMBA_NUM_THREADS`; the header says how many).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numba
import numpy as np
import pandas as pd
from archive import write_archive
from report import machine, markdown_table, write_section
from stages import stage_table

from rafostrack.config import method_overrides, with_overrides
from rafostrack.model.parallel import kernel_threads
from rafostrack.run.method import track_record
from rafostrack.run.one_float import TrackInputs, load_float
from rafostrack.sim.evaluate import association_accuracy, rmse_km
from rafostrack.sim.scenarios import sample_mission_dir

SAMPLE = sample_mission_dir() / "float767.csv"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--float-file", type=Path, default=SAMPLE)
    parser.add_argument("--archive-float", action="store_true", help="also time a simulated DIMES archive float")
    parser.add_argument("--methods", nargs="+", default=["exact", "bp", "unranked", "labeled"])
    parser.add_argument("--particles", type=int, nargs="+", default=[1000, 10000])
    parser.add_argument("--config", type=Path, action="append", default=[], help="an extra config layer")
    parser.add_argument("--profile", action="store_true")
    parser.add_argument("--report", type=Path, help="write the table into this Markdown file's speed section")
    args = parser.parse_args()

    with tempfile.TemporaryDirectory(prefix="rafostrack-speed-") as tmp:
        float_files = [args.float_file]
        if args.archive_float:
            (archived,) = write_archive(Path(tmp) / "dimes", 1).floats
            float_files.append(Path(tmp) / "dimes" / f"{archived.info.float_id}.csv")
        headers, rows, stages = [], [], []
        for float_file in float_files:
            header, float_rows, float_stages = _timed(float_file, args)
            headers.append(header)
            rows.extend(float_rows)
            stages.extend(float_stages)
    if args.report:
        write_section(args.report, "speed", _report(headers, pd.DataFrame(rows), stages))


def _timed(float_file: Path, args: argparse.Namespace) -> tuple[str, list[dict], list[tuple[str, pd.DataFrame]]]:
    """Track `float_file` with each method and particle count of `args`, printing as it goes:
    its header line, its table rows and (with `--profile`) its stage tables."""
    loaded = load_float(TrackInputs(float_file, config_files=tuple(args.config)))
    n_windows = len(loaded.record.windows)
    n_toas = sum(w.n_signals for w in loaded.record.windows)
    header = (
        f"{float_file.name}: {n_windows} windows, {n_toas} TOAs, {len(loaded.problem.beacons)} beacons; "
        f"{numba.get_num_threads()} kernel thread(s)"
    )
    print(header)
    truth = pd.read_csv(float_file.parent / "truth" / float_file.name, parse_dates=["time"])
    truth["time"] = truth["time"].dt.tz_localize(None)
    print(
        f"{'method':>9} {'particles':>9} {'total_s':>8} {'filter_s':>9} {'smoother_s':>10} {'calib_s':>8} "
        f"{'rmse_km':>8} {'labels':>7} {'ess/N':>6}"
    )
    rows, stages = [], []
    for method in args.methods:
        for particles in args.particles:
            config = with_overrides(loaded.problem.config, filter={**method_overrides(method), "particles": particles})
            started = time.perf_counter()
            out = track_record(loaded.problem.with_config(config), loaded.record)
            elapsed = time.perf_counter() - started
            rows.append({"float": float_file.stem, **_row(method, particles, elapsed, out, truth, loaded)})
            print(
                f"{method:>9} {particles:9d} {elapsed:8.2f} {out.seconds.filter_s:9.2f} {out.seconds.smoother_s:10.2f} "
                f"{out.seconds.calibrate_s:8.2f} {rmse_km(out.track, truth):8.2f} "
                f"{association_accuracy(out.labels, loaded.record):7.2%} "
                f"{np.median(out.counts.filter_ess) / particles:6.2f}",
                flush=True,
            )
            if args.profile:
                problem = loaded.problem.with_config(config)
                with kernel_threads(1):
                    table = stage_table(lambda: track_record(problem, loaded.record))  # noqa: B023
                title = f"Seconds per call and stage ({float_file.stem}, {method}, {particles} particles; stages.py):"
                print(f"\n{title}")
                print(table.to_string(index=False, float_format=lambda x: f"{x:.2f}"), "\n", flush=True)
                stages.append((title, table))
    return header, rows, stages


def _row(method: str, particles: int, elapsed_s: float, out, truth: pd.DataFrame, loaded) -> dict:
    """One line of the report's table: the timings and scores of one method and particle count."""
    return {
        "method": method,
        "particles": particles,
        "total_s": elapsed_s,
        "filter_s": out.seconds.filter_s,
        "smoother_s": out.seconds.smoother_s,
        "calib_s": out.seconds.calibrate_s,
        "rmse_km": rmse_km(out.track, truth),
        "labels": association_accuracy(out.labels, loaded.record),
        "ess/N": float(np.median(out.counts.filter_ess) / particles),
    }


def _report(headers: list[str], table: pd.DataFrame, stages: list[tuple[str, pd.DataFrame]]) -> str:
    """The speed section: what was tracked, on which machine, the table and the stage tables."""
    seconds = {c: (lambda x: f"{x:.2f}") for c in ("total_s", "filter_s", "smoother_s", "calib_s", "rmse_km", "ess/N")}
    tracked = "".join(f"{header}.\n\n" for header in headers)
    return (
        "Wall time of the whole method (every pass), split into filter, smoother and calibration; RMSE "
        "against the float's truth, labels right, median ESS of the last pass over N.\n\n"
        f"{tracked}Machine: {machine()}.\n\n" + markdown_table(table, {**seconds, "labels": lambda x: f"{x:.2%}"})
    ) + "".join(f"\n\n{title}\n\n" + markdown_table(stage, _two_decimals(stage)) for title, stage in stages)


def _two_decimals(table: pd.DataFrame) -> dict:
    """Every numeric column of `table` printed with two decimals."""
    return {c: (lambda x: f"{x:.2f}") for c in table.columns if pd.api.types.is_numeric_dtype(table[c])}


if __name__ == "__main__":
    main()
