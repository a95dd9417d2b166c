"""The mission's array fit alone on a DIMES-size archive: seconds and peak memory.

The issue's target: the fit for a 140-float, 2-year archive within 60 s and 2 GB beside the
tracking. Simulates the DIMES archive as `benchmarks/archive.py` does (the 140 real
launch/recovery pairs, the 12 real sources), and gives the fit each float's truth as its
tracked output (`sim.evaluate.truth_estimate`: the true track, every arrival labelled with
its source): the fit's cost depends on the floats, arrivals and sources, not on how they
were labelled, so the tracking (17-18 minutes of it) is left out. Fits the array twice,
each from the floats as `rafostrack batch` reads them back (`mission.floats.mission_float`):
with the tables as simulated (no value to release), and with three values wrong at once (an
offset +25 s, a drift +0.035 s/day, a position 18 km east: three releases, each fitted
again). Prints per fit the Gauss-Newton steps (each a pass over every float; after a
release the first only refits the weights), wall seconds, seconds per float and step, the
process's peak resident memory, and the values decided.

    python benchmarks/array_fit.py [--floats 140] [--seed 2026] [--jobs 1]

`--jobs N` maps the per-float work over N worker processes (`batch.pool.ordered_map`), as
the batch does with `--jobs`.
"""

from __future__ import annotations

import argparse
import dataclasses
import resource
import time
from collections.abc import Callable, Iterable

import numpy as np
from archive import SEED, dimes_archive_floats

from rafostrack.batch.pool import ordered_map
from rafostrack.config import Config, load_config
from rafostrack.domain import BeaconTable
from rafostrack.mission.array import calibrated_array
from rafostrack.mission.floats import MissionFloat, mission_float
from rafostrack.model.geodesy import displace
from rafostrack.sim.evaluate import truth_estimate
from rafostrack.sim.scenarios import dimes_scenario
from rafostrack.sim.simulate import SimulatedFloat, simulate_mission

OFFSET_S, DRIFT_S_PER_DAY, POSITION_KM = 25.0, 0.035, 18.0


def faulted(beacons: BeaconTable) -> BeaconTable:
    """Three values wrong at once: source 2's offset, source 5's drift, source 7's position."""
    offset = beacons.offset_s.copy()
    offset[1] += OFFSET_S
    drift = beacons.drift_s_per_day.copy()
    drift[4] += DRIFT_S_PER_DAY
    lat, lon = beacons.lat.copy(), beacons.lon.copy()
    lat[6], lon[6] = (float(v) for v in displace(lat[6], lon[6], POSITION_KM, 0.0))
    return dataclasses.replace(beacons, offset_s=offset, drift_s_per_day=drift, lat=lat, lon=lon)


def peak_mb() -> float:
    """This process's peak resident memory so far (MB): the fit's, where the floats, their
    blocks and the array system are held (a worker holds one float's work at a time)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _built(simulated: SimulatedFloat, beacons: BeaconTable, config: Config) -> MissionFloat | None:
    """The float as the fit reads it back from its outputs, its truth as its track and labels."""
    return mission_float(simulated.info.float_id, truth_estimate(simulated), beacons, simulated.info, config)


def fit_once(label: str, simulated: list[SimulatedFloat], beacons: BeaconTable, config: Config, jobs: int) -> None:
    """Build the mission's floats against `beacons`, fit the array and print one line."""
    started = time.perf_counter()
    floats = [f for s in simulated if (f := _built(s, beacons, config)) is not None]
    built = time.perf_counter() - started
    steps = 0

    def counted(mapped: Callable) -> Callable:
        def map_floats(work: Callable, tasks: Iterable) -> Iterable:
            nonlocal steps
            steps += 1
            return mapped(work, tasks)

        return map_floats

    with ordered_map(jobs) as mapped:
        started = time.perf_counter()
        array = calibrated_array(floats, beacons, config, counted(mapped))
        seconds = time.perf_counter() - started
    decided = ", ".join(f"{v.check.id} {v.check.field}" for v in array.decided()) or "none"
    arrivals = sum(f.n_arrivals for f in floats)
    print(
        f"{label:>9} {len(floats):6d} {arrivals:9d} {built:7.1f} {steps:5d} {seconds:8.1f} "
        f"{1000 * seconds / max(steps * len(floats), 1):9.1f} {peak_mb():8.0f}  {decided}",
        flush=True,
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--floats", type=int, default=None, help="the first K floats (default: all 140)")
    parser.add_argument("--seed", type=int, default=SEED)
    parser.add_argument("--jobs", type=int, default=1)
    args = parser.parse_args()

    started = time.perf_counter()
    beacons, config = dimes_scenario()[0], load_config()
    simulated = simulate_mission(
        beacons, dimes_archive_floats(args.floats), config.model, np.random.default_rng(args.seed)
    )
    days = np.mean([(s.info.end_time - s.info.launch_time) / np.timedelta64(1, "D") for s in simulated.floats])
    print(
        f"archive: {len(simulated.floats)} DIMES floats of {days:.0f} days on average, {len(beacons)} sources, "
        f"simulated in {time.perf_counter() - started:.0f} s; the fit's per-float work on {args.jobs} process(es)"
    )
    print(f"{'tables':>9} {'floats':>6} {'arrivals':>9} {'build s':>7} {'steps':>5} {'fit s':>8} "
          f"{'ms/float':>9} {'peak MB':>8}  decided")  # fmt: skip
    # numba's kernels compiled first, as a batch's tracking has compiled them before its fit
    warm_up = [f for s in simulated.floats[:2] if (f := _built(s, beacons, config)) is not None]
    calibrated_array(warm_up, beacons, config)
    fit_once("as given", simulated.floats, beacons, config, args.jobs)
    fit_once("3 wrong", simulated.floats, faulted(beacons), config, args.jobs)


if __name__ == "__main__":
    main()
