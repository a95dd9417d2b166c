"""What calibration does with a table value that the arrivals contradict (`metadata_checks`):
the timing fit is refitted with that value's prior released, so that the track, the clock
and the corrected beacon table follow the arrivals: a fix's sd widened to
`RELEASED_FIX_SD_KM`, the clock's launch offset to `RELEASED_CLOCK_SD_S` and its end offset
unmeasured, a source's offset and drift to `KalmanPriors.released_*`, and a source's
position made an unknown of `KalmanPriors.released_position_km`. For the particle filter, a
contradicted launch fix is then replaced by the position the arrivals support, and a
contradicted end fix is not used.

A GPS fix is data: one that the arrivals put more than `FIX_KEPT_BEYOND_KM` away is never
released nor moved (`kept_fix`). So far off, it is the track or the tables that are wrong
(a wrong source value pulls a float's whole track; a lost first pass contradicts every
fix), not the satellite fix; the check stays contradicted, with the distance and a note
saying so, and the float needs a look. (A launch longitude typed with the wrong sign,
thousands of km off, is `launch_check`'s case.) Likewise, where `[checks] release_sources`
is false (a batch's floats tracked with their mission's calibrated table), a source's
offset, drift or position is never released (`kept_source`): the mission's array fit
judged it on every float hearing the source, and one float alone cannot tell a source's
error from its own track's.

Values are released one at a time (`calibrate._checked_fit`): a wrong value pulls the fit,
and with it other values' checks (a wrong source position moves the track, and the end fix
then looks wrong too); once the culprit is released, its echoes are consistent again. The
arrivals' estimate of a value does not depend on its prior, so a released value stays
contradicted in the checks after its release: the checks always compare with the table.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import NDArray

from ..domain import BeaconTable, FloatInfo
from . import kalman
from .metadata_checks import CONTRADICTED, ESTIMATED, MetadataCheck

RELEASED_FIX_SD_KM = 100.0
RELEASED_CLOCK_SD_S = 120.0
FIX_KEPT_BEYOND_KM = 50.0
FIX_KEPT_NOTE = "kept as given: a GPS fix is data, so the track or the tables are wrong here; check them"
SOURCE_FIELDS = ("offset_s", "drift_s_per_day", "position")  # a source's values a float may release
SOURCE_KEPT_NOTE = (
    "kept as in the table: the mission's array fit judged it on every float hearing the source, "
    "so this float's track or labels are off here; check them"
)

TimingProblem = tuple[kalman.Problem, NDArray[np.intp], NDArray[np.float64]]  # problem, heard rows, mid days
Key = tuple[str, str]  # (id, field) of a table value


def key_of(check: MetadataCheck) -> Key:
    return (check.id, check.field)


def released_problem(built: TimingProblem, released: set[Key], beacons: BeaconTable) -> TimingProblem:
    """The timing problem with the prior of every value in `released` released (module docstring)."""
    problem, heard, mid = built
    fields = {field for _, field in released}
    start_sd, end_sd = problem.clock_sd_s
    names = [str(beacons.beacon_id[row]) for row in heard]
    timing = np.array([(n, "offset_s") in released or (n, "drift_s_per_day") in released for n in names], dtype=bool)
    moved = np.array([(n, "position") in released for n in names], dtype=bool)
    end_sd_km = problem.end_sd_km
    if "end_fix" in fields and end_sd_km is not None:
        end_sd_km = RELEASED_FIX_SD_KM
    return (
        dataclasses.replace(
            problem,
            launch_sd_km=RELEASED_FIX_SD_KM if "launch_fix" in fields else problem.launch_sd_km,
            end_sd_km=end_sd_km,
            clock_sd_s=(
                RELEASED_CLOCK_SD_S if "clock_offset_start_s" in fields else start_sd,
                None if "clock_offset_end_s" in fields else end_sd,
            ),
            released=timing,
            source_positions=bool(moved.any()),
            released_positions=moved if moved.any() else None,
        ),
        heard,
        mid,
    )


def kept_fix(check: MetadataCheck) -> bool:
    """A fix the arrivals contradict by more than `FIX_KEPT_BEYOND_KM`: kept (module docstring)."""
    far = isinstance(check.supported, float) and check.supported > FIX_KEPT_BEYOND_KM
    return check.field in ("launch_fix", "end_fix") and check.outcome == CONTRADICTED and far


def kept_source(check: MetadataCheck, release_sources: bool) -> bool:
    """A source's offset, drift or position the arrivals contradict, where sources are not
    released (`[checks] release_sources` false: a mission's array judged them): kept."""
    return not release_sources and check.field in SOURCE_FIELDS and check.outcome == CONTRADICTED


def releasable(check: MetadataCheck, release_sources: bool = True) -> bool:
    """A contradicted value calibration may release: any but a fix it keeps, or a source's
    value where sources are not released (`kept_source`)."""
    return check.outcome == CONTRADICTED and not kept_fix(check) and not kept_source(check, release_sources)


def used(check: MetadataCheck, release_sources: bool = True) -> MetadataCheck:
    """`check` with the value the track uses: the arrivals' where they contradict the table or
    the table has none, the table's otherwise (and for a fix or source value it keeps, with
    its note)."""
    if kept_fix(check):
        return dataclasses.replace(check, used=check.given, note=FIX_KEPT_NOTE)
    if kept_source(check, release_sources):
        return dataclasses.replace(check, used=check.given, note=SOURCE_KEPT_NOTE)
    value = check.supported if check.outcome in (CONTRADICTED, ESTIMATED) else check.given
    return dataclasses.replace(check, used=value)


def with_supported_fixes(info: FloatInfo, checks: list[MetadataCheck]) -> FloatInfo:
    """`info` for the particle filter after the checks: a contradicted launch fix replaced
    by the position the arrivals support (the filter needs a start), a contradicted end fix
    dropped (the end of the track then rests on the arrivals; put in the arrivals' place
    with the fix's own sd, a false alarm from a lost first pass pinned the next pass to a
    position hundreds of km off)."""
    for check in checks:
        if not releasable(check) or check.supported_lat_lon is None:
            continue
        if check.field == "launch_fix":
            lat, lon = check.supported_lat_lon
            info = dataclasses.replace(info, launch_lat=lat, launch_lon=lon)
        elif check.field == "end_fix":
            info = dataclasses.replace(info, end_lat=float("nan"), end_lon=float("nan"))
    return info
