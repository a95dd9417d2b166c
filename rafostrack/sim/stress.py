"""A stress scenario: missions from a generator that is NOT the tracker's model.

The tracker's own simulator (`rafostrack.sim.simulate`) draws from the tracker's model, so it
cannot show what the model lacks. This generator shares only geometry with the tracker
(`geodesy`: ranges and displacements) and the file format; its physics is its own, every
phenomenon an independent knob of `StressConfig`, intensities drawn per float or beacon:

- geometry: the real DIMES array (all 12 sources, March-October 2010) or the real Weddell
  Sea array (the 11 sources active April-November 2008, with their real offsets and clock
  drifts); floats launched where at least 3 sources are within 900 km, and drawn again if
  their drift leaves the array (`min_covered_fraction`: fewer than 3 sources within their
  half-detection range on more than 10% of days);
- drift: a meandering zonal jet (core speed and sign per geometry), a field of coherent
  rotating eddies drifting with it (a float near one loops around it for weeks), and
  small-scale OU velocity noise; integrated hourly (second-order Runge-Kutta);
- recording gaps of several days (no windows at all), scattered missing days, and windows
  that stored nothing;
- detection: per beacon a peak probability and a range at which it halves (logistic
  fall-off of per-beacon width), and a two-state Markov "bad propagation" regime per beacon
  (detection x 0.3 while bad);
- multipath: per float a fraction of detected arrivals delayed by a lognormal delay
  (median 20 s, 5-60 s); half of them replace the direct arrival, half come as an echo
  after it; their label is their beacon;
- source outages: one or two beacons silent for 20-60 days, not stated in beacons.csv;
- clocks: the float clock wanders smoothly (+-1-3 s) about the linear model given in
  floats.csv, which drifts from the launch's offset to the end's (within +-2 s, or by
  `clock_end_offset_s` like real floats); each source's clock drifts +-0.01 s/day from its
  catalogue value;
- floats that never surfaced (`never_surfaced_share`): no end fix and no end clock;
- metadata faults (`faults`, see `rafostrack.sim.faults`): wrong or missing values written in
  floats.csv and beacons.csv, recorded in `truth/faults.json`; the truth is unchanged;
- sound speed: the truth's effective sound speed differs from the tracker's default (1480
  m/s) by a per-geometry amount, and per beacon by a little more;
- TOA noise: Student-t (5 dof) scaled to a per-float sd of 1.5-3 s;
- clutter: Poisson per window at the float's rate, uniform in the window, and occasional
  bursts of 3-6 more.
The float stores the earliest `max_signals` signals of its window.

All randomness comes from one `numpy.random.Generator`, drawn in a fixed order (the
geometry's beacons, then float by float: launch, drift, events, then window by window), so
a seed gives byte-identical files. The knobs added later draw from their own generators,
children of the same seed (`substream`: the end clocks and surfacing float by float, then
the faults), so that turning them on leaves every other draw as it was.
`truth/<float_id>.json` records what happened to each float (gaps, outages, eddies met,
multipath fraction, true sound speed, ...).

This module makes and writes missions; the knobs are `stress_config`, the array and the
drift `stress_world`, one float's draws and windows `stress_float`.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..domain import BeaconTable, FloatInfo
from ..io.atomic import write_text_atomic
from .faults import SOURCE_KINDS, InjectedFault, SourceSetting, apply_faults, draw_faults
from .stress_config import StressConfig
from .stress_float import CLOCK_STREAM, StressFloat, simulate_float, substream
from .stress_world import DAY_NS, GEOMETRIES, catalogue

__all__ = [
    "DAY_NS",
    "FAULT_STREAM",
    "StressConfig",
    "StressFloat",
    "StressMission",
    "heard_sources",
    "simulate_float",
    "simulate_stress",
    "substream",
    "with_faults",
    "with_knobs",
    "write_stress_mission",
    "written_tables",
]

FAULT_STREAM = 33  # `substream` key of the faults (`stress_float.CLOCK_STREAM`: the end clocks)
MIN_HEARD_SHARE = 0.2  # a source fault's candidates: heard in this share of every float's windows
DEFAULT_KNOBS = StressConfig()  # every phenomenon on, at its default range


@dataclass(frozen=True)
class StressMission:
    """A mission: its correct tables (`beacons`, the floats' `info`) and the metadata faults
    written over them (None: none asked for; `written_tables` gives the tables as written)."""

    geometry: str
    beacons: BeaconTable  # the catalogue (offsets and drifts), as it should be written
    floats: list[StressFloat]
    faults: tuple[InjectedFault, ...] | None = None


def heard_sources(mission: StressMission, at_least: int = 1) -> list[str]:
    """The sources heard (true labels) in at least `MIN_HEARD_SHARE` of every float's
    windows, best heard first; at least the `at_least` best heard."""
    ids = [str(b) for b in mission.beacons.beacon_id]
    share = np.ones(len(ids))
    for f in mission.floats:
        heard = [set(w.beacon_id or ()) for w in f.record.windows]
        share = np.minimum(share, np.array([np.mean([b in h for h in heard]) if heard else 0.0 for b in ids]))
    order = np.argsort(-share, kind="stable")
    n = max(int(np.sum(share >= MIN_HEARD_SHARE)), min(at_least, len(ids)))
    return [ids[i] for i in order[:n]]


def with_faults(mission: StressMission, cfg: StressConfig, rng: np.random.Generator) -> StressMission:
    """`mission` with the faults `cfg.faults` (drawn from `rng`; source faults on
    `heard_sources`), the truth unchanged."""
    geometry = GEOMETRIES[mission.geometry]
    first = min(f.truth["time"].iloc[0] for f in mission.floats)
    last = max(f.truth["time"].iloc[-1] for f in mission.floats)
    setting = SourceSetting(geometry.slot_s, geometry.window_s, (np.datetime64(first, "ns"), np.datetime64(last, "ns")))
    candidates = heard_sources(mission, len(set(cfg.faults) & set(SOURCE_KINDS)))
    infos = [f.info for f in mission.floats]
    faults = draw_faults(cfg.faults, mission.beacons, infos, candidates, setting, rng, cfg.fault_float_share)
    return dataclasses.replace(mission, faults=tuple(faults))


def written_tables(mission: StressMission) -> tuple[BeaconTable, list[FloatInfo]]:
    """beacons.csv's and floats.csv's contents as written: the correct tables with the faults."""
    return apply_faults(mission.beacons, [f.info for f in mission.floats], mission.faults or ())


def simulate_stress(
    geometry: str, n_floats: int, rng: np.random.Generator, cfg: StressConfig = DEFAULT_KNOBS, prefix: str = "s"
) -> StressMission:
    """`n_floats` floats of one geometry, with the faults `cfg.faults` (`with_faults`, from
    `substream(rng, FAULT_STREAM)`)."""
    geo = GEOMETRIES[geometry]
    beacons = catalogue(geo)
    side = substream(rng, CLOCK_STREAM)
    floats = [simulate_float(f"{prefix}{k + 1:02d}", beacons, geo, cfg, rng, side) for k in range(n_floats)]
    mission = StressMission(geometry, beacons, floats)
    return with_faults(mission, cfg, substream(rng, FAULT_STREAM)) if cfg.faults else mission


def write_stress_mission(mission: StressMission, outdir: Path) -> None:
    """A mission directory: beacons.csv, floats.csv (as written: with the faults), the
    arrival files (true labels in beacon_id), truth/<float_id>.csv, truth/<float_id>.json and,
    when faults were asked for, truth/faults.json. No rafostrack.toml: the tracker runs with
    its defaults, knowing only what a user would know."""
    from .mission_writer import write_faults, write_mission_files

    beacons, infos = written_tables(mission)
    floats = [(info, f.record, f.truth) for info, f in zip(infos, mission.floats, strict=True)]
    write_mission_files(beacons, floats, Path(outdir))
    for f in mission.floats:
        write_text_atomic(Path(outdir) / "truth" / f"{f.info.float_id}.json", json.dumps(f.events, indent=2) + "\n")
    if mission.faults is not None:
        write_faults(mission.faults, Path(outdir))


def with_knobs(cfg: StressConfig, settings: dict[str, Any]) -> StressConfig:
    """`cfg` with some knobs replaced (names checked)."""
    names = {f.name for f in dataclasses.fields(StressConfig)}
    unknown = sorted(set(settings) - names)
    if unknown:
        raise ValueError(f"unknown stress knob(s): {', '.join(unknown)}; known: {', '.join(sorted(names))}")
    return dataclasses.replace(cfg, **settings)
