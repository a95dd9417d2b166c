"""The array of a mission fitted on its tracked floats: the sources they hardly labelled
scanned for (`source_scan`), their piled-up arrivals labelled, then the array fit and its
judgement (`array`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from ..domain import BeaconTable
from .array import MissionArray, calibrated_array
from .array_fit import FloatMap
from .floats import mission_float
from .from_outputs import TrackedFloat
from .source_scan import Pile, relabelled, scan_sources


@dataclass(frozen=True)
class MissionFit:
    """The mission's array and the piles the scan found on the way."""

    array: MissionArray
    piles: list[Pile]


def fit_mission_array(
    tracked: Sequence[TrackedFloat], map_floats: FloatMap = map, tracked_with: BeaconTable | None = None
) -> MissionFit | None:
    """Scan, relabel, fit and judge (module docstring); None when no float has enough
    confident arrivals. The mission's configuration and tables are its first float's;
    `map_floats` maps the fit's per-float work (`array_fit.float_step`); `tracked_with`: the
    table the floats were tracked with, when not the one as given (`calibrated_array`)."""
    if not tracked:
        return None
    piles = scan_sources([(t.estimate, t.problem) for t in tracked])
    floats = []
    for t in tracked:
        estimate = relabelled(t.estimate, t.problem, piles) if piles else t.estimate
        p = t.problem
        built = mission_float(p.info.float_id, estimate, p.beacons, p.info, p.config, t.hyper)
        if built is not None:
            floats.append(built)
    if not floats:
        return None
    first = tracked[0].problem
    return MissionFit(calibrated_array(floats, first.beacons, first.config, map_floats, tracked_with), piles)
