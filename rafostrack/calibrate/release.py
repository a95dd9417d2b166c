"""What calibration does with a table value that the arrivals contradict (`metadata_checks`):
the timing fit is refitted with that value's prior released (a fix's sd to
`RELEASED_FIX_SD_KM`, a source's offset and drift to `KalmanPriors.released_*`) or, for the
float clock's offsets, the arrivals' values taken as the measurements (with the arrivals'
sd), so that the track, the clock and the corrected beacon table follow the arrivals; a
contradicted fix is replaced by the position the arrivals support. Values the arrivals cannot decide keep the table's.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import NDArray

from ..domain import BeaconTable, FloatInfo
from . import kalman
from .metadata_checks import CONTRADICTED, ESTIMATED, MetadataCheck

RELEASED_FIX_SD_KM = 100.0

TimingProblem = tuple[kalman.Problem, NDArray[np.intp], NDArray[np.float64]]  # problem, heard rows, mid days


def released_problem(built: TimingProblem, checks: list[MetadataCheck], beacons: BeaconTable) -> TimingProblem:
    """The timing problem with the prior of every contradicted value released (module docstring)."""
    problem, heard, mid = built
    contradicted = {(c.id, c.field) for c in checks if c.outcome == CONTRADICTED}
    fields = {field for _, field in contradicted}
    start_sd, end_sd = problem.clock_sd_s
    sources = {name for name, field in contradicted if field in ("offset_s", "drift_s_per_day")}
    released = np.array([str(beacons.beacon_id[row]) in sources for row in heard], dtype=bool)
    return (
        dataclasses.replace(
            problem,
            launch_sd_km=RELEASED_FIX_SD_KM if "launch_fix" in fields else problem.launch_sd_km,
            end_sd_km=RELEASED_FIX_SD_KM
            if "end_fix" in fields and problem.end_sd_km is not None
            else problem.end_sd_km,
            clock_sd_s=(
                _clock_sd(checks, "clock_offset_start_s", start_sd) or start_sd,
                _clock_sd(checks, "clock_offset_end_s", end_sd),
            ),
            released=released,
        ),
        heard,
        mid,
    )


def _clock_sd(checks: list[MetadataCheck], field: str, sd: float | None) -> float | None:
    """A clock offset's prior sd: the arrivals' sd where they contradict the table (the offset
    itself is then theirs, `with_supported_clock`), else as it was."""
    for check in checks:
        if check.field == field and check.outcome == CONTRADICTED and check.sd is not None and sd is not None:
            return max(sd, check.sd)
    return sd


def with_supported_clock(info: FloatInfo, checks: list[MetadataCheck]) -> FloatInfo:
    """`info` with each contradicted clock offset replaced by the arrivals' value."""
    for check in checks:
        if check.outcome != CONTRADICTED or check.supported is None:
            continue
        if check.field == "clock_offset_start_s":
            info = dataclasses.replace(info, clock_offset_start_s=check.supported)
        elif check.field == "clock_offset_end_s":
            info = dataclasses.replace(info, clock_offset_end_s=check.supported)
    return info


def used(check: MetadataCheck) -> MetadataCheck:
    """`check` with the value the track uses: the arrivals' where they contradict the table or
    the table has none, the table's otherwise."""
    value = check.supported if check.outcome in (CONTRADICTED, ESTIMATED) else check.given
    return dataclasses.replace(check, used=value)


def with_supported_fixes(info: FloatInfo, checks: list[MetadataCheck]) -> FloatInfo:
    """`info` with each contradicted fix replaced by the position the arrivals support."""
    for check in checks:
        if check.outcome != CONTRADICTED or check.supported_lat_lon is None:
            continue
        lat, lon = check.supported_lat_lon
        if check.field == "launch_fix":
            info = dataclasses.replace(info, launch_lat=lat, launch_lon=lon)
        elif check.field == "end_fix":
            info = dataclasses.replace(info, end_lat=lat, end_lon=lon)
    return info
