"""The `abc` association engine against `exact` on stress-scenario floats.

Simulates floats with `rafostrack.sim.stress` (the independent generator of benchmarks/
robustness.py: eddying drift, gaps, range-faded and Markov-fading detection, multipath,
outages, clock wander, a sound-speed mismatch, heavy-tailed noise, clutter bursts), writes
them as mission directories and tracks every float from its files (`run.one_float.track_float`)
with the default settings, once with `--engine exact` and once with `--engine abc`, the
only difference. Prints, per float and engine: RMSE, p95 and max error (km), labels right
(the fraction of stored TOAs given their true beacon or clutter), 95%-ellipse coverage,
wall time; then the paired differences abc - exact over the floats, with standard errors.

The full robustness set (24 floats of 240 days) is heavy for abc; the default here is a
subset: 3 DIMES and 3 Weddell floats of 120 days at clutter rate 2.

    nice -n 10 python benchmarks/abc_engine.py [--floats-per-geometry 3] [--days 120]
        [--clutter 2] [--seed 2026] [--particles N] [--workers 1] [--out DIR] [--csv FILE]
"""

from __future__ import annotations

import argparse
import multiprocessing
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from papers.common import mean_se
from rafostrack.batch.workers import single_threaded_math
from rafostrack.run.one_float import TrackInputs, load_float, track_float
from rafostrack.sim.evaluate import association_accuracy, inside_ellipse, position_errors_km
from rafostrack.sim.stress import StressConfig, simulate_stress, write_stress_mission
from rafostrack.summaries.posterior import ELLIPSE_95_SCALE

ENGINES = ("exact", "abc")
GEOMETRIES = ("dimes", "weddell")


def make_missions(root: Path, per_geometry: int, days: int, clutter: float, seed: int) -> list[Path]:
    """`per_geometry` floats of each geometry; their float files."""
    files = []
    for k, geometry in enumerate(GEOMETRIES):
        cfg = StressConfig(days=days, clutter_rate=clutter)
        mission = simulate_stress(geometry, per_geometry, np.random.default_rng([seed, k]), cfg, prefix=geometry[0])
        outdir = root / geometry
        write_stress_mission(mission, outdir)
        files += [outdir / f"{f.info.float_id}.csv" for f in mission.floats]
    return files


def score(task: tuple[Path, Path, str, int | None]) -> dict[str, Any]:
    """Track one float with one engine and score it against the truth."""
    float_file, out_root, engine, particles = task
    truth = pd.read_csv(float_file.parent / "truth" / f"{float_file.stem}.csv", parse_dates=["time"])
    truth["time"] = truth["time"].dt.tz_localize(None)
    overrides: dict[str, dict[str, Any]] = {"filter": {"engine": engine}}
    if particles is not None:
        overrides["filter"]["particles"] = particles
    started = time.perf_counter()
    result = track_float(TrackInputs(float_file, overrides=overrides), out_root / engine, plots=False)
    seconds = time.perf_counter() - started
    track = result.output.track
    err = position_errors_km(track, truth)
    labelled = load_float(TrackInputs(float_file, overrides={"filter": {"likelihood": "labeled"}})).record
    return {
        "float": float_file.stem,
        "engine": engine,
        "rmse_km": float(np.sqrt(np.mean(err**2))),
        "p95_km": float(np.percentile(err, 95)),
        "max_km": float(err.max()),
        "labels": association_accuracy(result.output.labels, labelled),
        "cover95": float(np.mean(inside_ellipse(track, truth, ELLIPSE_95_SCALE))),
        "windows": len(track),
        "seconds": seconds,
        "ms_per_window": 1e3 * seconds / max(len(track), 1),
    }


def paired(table: pd.DataFrame) -> pd.DataFrame:
    """Per score: mean over floats of abc - exact and its standard error."""
    wide = table.pivot(index="float", columns="engine")
    rows = []
    for col in ("rmse_km", "p95_km", "max_km", "labels", "cover95", "seconds"):
        diff = wide[col]["abc"] - wide[col]["exact"]
        mean, se = mean_se(diff)
        rows.append(
            {
                "score": col,
                "exact_mean": float(wide[col]["exact"].mean()),
                "abc_mean": float(wide[col]["abc"].mean()),
                "abc_minus_exact": mean,
                "se": se,
                "abc_worse_floats": int((diff < 0).sum() if col in ("labels", "cover95") else (diff > 0).sum()),
            }
        )
    return pd.DataFrame(rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--floats-per-geometry", type=int, default=3)
    parser.add_argument("--days", type=int, default=120)
    parser.add_argument("--clutter", type=float, default=2.0)
    parser.add_argument("--seed", type=int, default=2026)
    parser.add_argument("--particles", type=int, default=None, help="override [filter] particles")
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--out", type=Path, help="keep the missions and outputs here")
    parser.add_argument("--csv", type=Path, help="write the per-float table here")
    args = parser.parse_args()
    root = args.out or Path(tempfile.mkdtemp(prefix="rafostrack-abc-engine-"))
    root.mkdir(parents=True, exist_ok=True)
    files = make_missions(root / "missions", args.floats_per_geometry, args.days, args.clutter, args.seed)
    (root / "out").mkdir(exist_ok=True)
    tasks = [(f, root / "out", engine, args.particles) for f in files for engine in ENGINES]
    started = time.perf_counter()
    if args.workers > 1:
        context = multiprocessing.get_context("forkserver")  # fresh workers: numba single-threaded too
        with single_threaded_math(), ProcessPoolExecutor(args.workers, mp_context=context) as pool:
            rows = list(pool.map(score, tasks))
    else:
        rows = [score(t) for t in tasks]
    table = pd.DataFrame(rows)
    pd.set_option("display.width", 200)
    print(table.to_string(index=False, float_format=lambda x: f"{x:.3f}"))
    print(f"\n{len(files)} floats x {len(ENGINES)} engines in {time.perf_counter() - started:.0f} s; outputs in {root}")
    print("\nabc - exact over the floats (mean, standard error; worse = floats where abc is worse):")
    print(paired(table).to_string(index=False, float_format=lambda x: f"{x:.3f}"))
    if args.csv:
        table.to_csv(args.csv, index=False)


if __name__ == "__main__":
    main()
