"""Leg fits against the particle smoother on stress-scenario floats (velocities with truth).

The floats are those of `benchmarks/robustness.py` (same generator, seed and grouping:
DIMES and Weddell arrays, clutter 1, 2, 3, 240 days); by default the first float of each
of the six groups (`--per-group 1`). Each float is tracked by the smoother with the
default settings and then fitted with legs (`rafostrack.legs.floats.legs_float`, as
`rafostrack legs` does). Printed per float:

- position RMSE (km) at the windows of the smoother and of the legs (posterior mean);
- velocity RMSE (km/day) against the true mean velocity over each day between two
  windows a day apart (and over 5 days: `vel5_*`): the smoother's finite difference of its
  positions, and the legs' posterior mean of the same span's mean velocity;
- 95% coverage: of positions (ellipses) for both; of the daily velocities for the legs,
  from the posterior of the leg velocity plus the model's wiggle (the float's departures
  from its legs, N(0, s^2) per window, add 2 s^2 / dt^2 to the variance of a velocity);
- run time (s): the smoother, and the leg fit after it (grids + sampler).

    nice -n 10 python benchmarks/legs.py [--per-group 1] [--days 240] [--seed 2026] [--out DIR] [--csv FILE]
    OMP_NUM_THREADS=1 taskset -c 0 python benchmarks/legs.py --sample-float   # the 2-year float's timing

`--sample-float` instead times the 2-year sample float (float767, 729 windows): the
smoother, then the leg fit (grids + sampler), on whatever cores it is given.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from scipy.stats import chi2

from rafostrack.legs.floats import legs_float
from rafostrack.legs.summaries import velocity_samples
from rafostrack.model.geodesy import local_offsets_km
from rafostrack.run.one_float import TrackInputs
from rafostrack.sim.evaluate import inside_ellipse, position_errors_km
from rafostrack.sim.scenarios import sample_mission_dir
from rafostrack.summaries.posterior import ELLIPSE_95_SCALE

sys.path.insert(0, str(Path(__file__).parent))
from robustness import make_missions

FLOATS_PER_GROUP_IN_ROBUSTNESS = 4  # its default 24 floats over 6 groups


def _truth(float_file: Path) -> pd.DataFrame:
    truth = pd.read_csv(float_file.parent / "truth" / f"{float_file.stem}.csv", parse_dates=["time"])
    truth["time"] = truth["time"].dt.tz_localize(None)
    return truth


def pairs(track_times: pd.Series, truth: pd.DataFrame, days: int) -> tuple[np.ndarray, np.ndarray]:
    """Indices (into `truth`) of true positions `days` apart, both at windows."""
    times = truth["time"].to_numpy()
    at_window = truth["time"].isin(set(pd.to_datetime(track_times))).to_numpy()
    later = np.searchsorted(times, times + np.timedelta64(days, "D"))
    ok = (later < len(times)) & at_window
    ok[ok] &= (times[later[ok]] == times[ok] + np.timedelta64(days, "D")) & at_window[later[ok]]
    first = np.flatnonzero(ok)
    return first, later[first]


def velocity_of(frame: pd.DataFrame, a: np.ndarray, b: np.ndarray, days: np.ndarray) -> np.ndarray:
    """(n, 2) east/north km/day from row a to row b of a lat/lon frame."""
    east, north = local_offsets_km(frame["lat"].to_numpy()[b], frame["lon"].to_numpy()[b],
                                   frame["lat"].to_numpy()[a], frame["lon"].to_numpy()[a])  # fmt: skip
    return np.column_stack([east, north]) / days[:, None]


def score(float_file: Path, out_root: Path) -> dict[str, Any]:
    truth = _truth(float_file)
    started = time.perf_counter()
    result = legs_float(TrackInputs(float_file), out_root, plots=False)
    total = time.perf_counter() - started
    fit = result.fit
    smoother = fit.smoother.track
    legs_track = pd.read_parquet(result.out_dir / "legs_track.parquet")
    legs_track["time"] = legs_track["time"].dt.tz_localize(None)
    err_s, err_l = position_errors_km(smoother, truth), position_errors_km(legs_track, truth)
    by_time = smoother.set_index(pd.to_datetime(smoother["time"]))[["lat", "lon"]]
    wiggle2 = float(np.mean(np.square(np.array(fit.evidence.wiggle_sd_km)[fit.chain.levels])))
    rmse = lambda e: float(np.sqrt(np.mean(np.sum(np.atleast_2d(e) ** 2, axis=-1))))  # noqa: E731
    vel: dict[int, dict[str, Any]] = {}
    for span in (1, 5):
        a, b = pairs(smoother["time"], truth, span)
        days = np.full(len(a), float(span))
        v_true = velocity_of(truth, a, b, days)
        both = pd.concat([by_time.loc[truth["time"].iloc[a]], by_time.loc[truth["time"].iloc[b]]], ignore_index=True)
        v_smooth = velocity_of(both, np.arange(len(a)), np.arange(len(a)) + len(a), days)
        start_days = (truth["time"].iloc[a].to_numpy() - fit.epoch) / np.timedelta64(1, "D")
        samples = velocity_samples(fit.chain, start_days, start_days + days)  # (S, n, 2), plane km/day
        v_legs = samples.mean(axis=0)
        dev = samples - v_legs
        cov = np.einsum("sni,snj->nij", dev, dev) / max(len(samples) - 1, 1)
        cov = cov + (2 * wiggle2 / span**2 + 1e-9) * np.eye(2)
        resid = v_true - v_legs
        maha = np.einsum("ni,nij,nj->n", resid, np.linalg.inv(cov), resid)
        vel[span] = {"smooth": rmse(v_smooth - v_true), "legs": rmse(v_legs - v_true), "true": rmse(v_true),
                     "cover": float(np.mean(maha <= chi2.ppf(0.95, 2))), "n": len(a)}  # fmt: skip
    return {
        "float": float_file.stem,
        "windows": len(smoother),
        "legs_map": fit.chain.best.n_legs,
        "pos_rmse_smoother_km": float(np.sqrt(np.mean(err_s**2))),
        "pos_rmse_legs_km": float(np.sqrt(np.mean(err_l**2))),
        "vel_rmse_smoother_fd": vel[1]["smooth"],
        "vel_rmse_legs": vel[1]["legs"],
        "true_speed_rms": vel[1]["true"],
        "vel5_rmse_smoother_fd": vel[5]["smooth"],
        "vel5_rmse_legs": vel[5]["legs"],
        "cover95_smoother": float(np.mean(inside_ellipse(smoother, truth, ELLIPSE_95_SCALE))),
        "cover95_legs": float(np.mean(inside_ellipse(legs_track, truth, ELLIPSE_95_SCALE))),
        "vel_cover95_legs": vel[1]["cover"],
        "vel5_cover95_legs": vel[5]["cover"],
        "wiggle_km": float(np.sqrt(wiggle2)),
        "days_scored": vel[1]["n"],
        "smoother_s": fit.timings["smoother_s"],
        "legs_fit_s": fit.timings["fit_s"],
        "total_s": total,
    }


SAMPLE_FLOAT = sample_mission_dir() / "float767.csv"


def time_sample_float(out: Path) -> None:
    result = legs_float(TrackInputs(SAMPLE_FLOAT), out, plots=False)
    t = result.fit.timings
    print(
        f"{result.float_id}: {result.run['windows']} windows, {result.fit.chain.best.n_legs} legs; smoother "
        f"{t['smoother_s']:.1f} s,"
        f" leg fit {t['fit_s']:.1f} s (grids {t['grids_s']:.1f} s, sampler "
        f"{t['sampler_s']:.1f} s, {result.run['iterations']} iterations); total {result.run['runtime_s']:.1f} s"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--per-group", type=int, default=1, help="floats per (geometry, clutter) group")
    parser.add_argument("--days", type=int, default=240)
    parser.add_argument("--seed", type=int, default=2026)
    parser.add_argument("--out", type=Path, help="keep the missions and outputs here")
    parser.add_argument("--csv", type=Path, help="write the per-float table here")
    parser.add_argument("--sample-float", action="store_true", help="time the 2-year sample float instead")
    args = parser.parse_args()
    root = args.out or Path(tempfile.mkdtemp(prefix="rafostrack-legs-"))
    if args.sample_float:
        time_sample_float(root)
        return
    files = make_missions(root / "missions", 6 * FLOATS_PER_GROUP_IN_ROBUSTNESS, args.days, args.seed)
    chosen = [f for k, f in enumerate(files) if k % FLOATS_PER_GROUP_IN_ROBUSTNESS < args.per_group]
    print(f"floats: {', '.join(f.stem for f in chosen)} (robustness set, seed {args.seed}, {args.days} days)")
    rows = [score(f, root / "out") for f in chosen]
    table = pd.DataFrame(rows)
    pd.set_option("display.width", 250)
    print(table.to_string(index=False, float_format=lambda x: f"{x:.2f}"))
    means = table.drop(columns=["float"]).mean()
    print("\nmean over floats:")
    print(means.to_string(float_format=lambda x: f"{x:.3f}"))
    for col in ("vel", "vel5"):
        better = int((table[f"{col}_rmse_legs"] < table[f"{col}_rmse_smoother_fd"]).sum())
        print(f"{col}: legs' velocity RMSE below the smoother's finite difference on {better}/{len(table)} floats")
    if args.csv:
        table.to_csv(args.csv, index=False)


if __name__ == "__main__":
    main()
