"""The float's listening window (floats.csv window_s) against its arrivals.

Too short (`late_window_check`, before tracking): the reader leaves out the TOAs later than
window_s (`ArrivalRecord.late`). At least `MIN_LATE_TOAS` of them say the float listened
longer (one or two are more likely corrupt entries than a wrong window, and a value that
recurs in `FILL_REPEATS` or more windows is a fill value such as 9999, not an arrival):
contradicted, the arrivals support the latest of them, and the record is tracked with that
window, its late TOAs up to it taken back (`io.records.with_longer_window`).

Too long (`window_check`, in calibration): a window that stored fewer than max_signals TOAs
was listened to its end, and the model spreads clutter uniformly over it. At the calibrated
rate lambda per window, the clutter of the n such windows falls past the record's latest
TOA T as a Poisson count of mean

    mu = n lambda (W - T) / W,

and none fell there: if the given W is right, an event of probability exp(-mu). With
c = -ln Phi(-z) (z = `[checks] launch_z_score`: one check per float, as the launch fix's),
the window is

- contradicted where mu > c: the float stopped listening before W. The arrivals support T,
  the least window they allow; the track uses it, with the clutter rate per window refitted
  to the shorter windows;
- consistent where mu <= -ln 0.05 (the given W lies within the arrivals' 95% bound);
- undetermined in between, or where the clutter is too sparse to bound the window at all
  (n lambda <= c: even a whole window's length past T would be expected to catch fewer
  clutter signals than the test needs).

A float that fills its max_signals in almost every window rarely listens to the end, so
there a window too long is mostly undetermined; it then also changes the track little
(docs/decisions.md).
"""

from __future__ import annotations

import dataclasses
import math
from collections import Counter

from scipy.special import log_ndtr

from ..domain import ArrivalRecord, FloatInfo
from .metadata_checks import CONSISTENT, CONTRADICTED, UNDETERMINED, MetadataCheck, float_source
from .noise import clutter_exposure

MIN_LATE_TOAS = 3
FILL_REPEATS = 3
CONSISTENT_MU = -math.log(0.05)
FIELD = "window_s"
TOOK_BACK = "tracked with the arrivals' value, the TOAs past the given window taken back"


def late_window_check(record: ArrivalRecord, info: FloatInfo) -> MetadataCheck | None:
    """A window too short, where at least `MIN_LATE_TOAS` TOAs lie past it, fill values
    aside (module docstring); None otherwise."""
    repeats = Counter(a.toa_s for a in record.late)
    late = [a.toa_s for a in record.late if repeats[a.toa_s] < FILL_REPEATS]
    if len(late) < MIN_LATE_TOAS:
        return None
    file, line = float_source(info)
    latest = float(math.ceil(max(late)))
    return MetadataCheck(file, line, info.float_id, FIELD, float(info.window_s), latest, None, "s", CONTRADICTED,
                         used=latest, note=TOOK_BACK)  # fmt: skip


def window_check(record: ArrivalRecord, info: FloatInfo, clutter_rate: float, z: float) -> MetadataCheck:
    """`info.window_s` against the clutter past the latest TOA of `record`, at
    `clutter_rate` signals per window: a window too long (module docstring)."""
    file, line = float_source(info)
    given = float(info.window_s)

    def check(supported: float | None, outcome: str) -> MetadataCheck:
        used = supported if outcome == CONTRADICTED else given
        return MetadataCheck(file, line, info.float_id, FIELD, given, supported, None, "s", outcome, used=used)

    latest = max((float(w.toa_s[-1]) for w in record.windows if w.n_signals), default=0.0)
    listened = sum(1 for w in record.windows if w.n_signals < info.max_signals)
    reach = listened * clutter_rate  # the clutter these windows catch over a whole window
    needed = -float(log_ndtr(-z))
    if not math.isfinite(reach) or reach <= needed:
        return check(None, UNDETERMINED)
    mu = reach * (given - latest) / given
    if mu > needed:
        return check(float(math.ceil(latest)), CONTRADICTED)
    return check(float(math.ceil(latest)), CONSISTENT if mu <= CONSISTENT_MU else UNDETERMINED)


def with_supported_window(
    info: FloatInfo, clutter_rate: float, check: MetadataCheck, record: ArrivalRecord
) -> tuple[FloatInfo, float]:
    """`info` and the clutter rate per window for the track: the window the arrivals support
    where `check` contradicts a window too long, the rate refitted to it (the same expected
    clutter count over the windows' exposure at the new length, `noise.fit_clutter_rate`);
    as given otherwise."""
    if not isinstance(check.used, float) or check.used == check.given:
        return info, clutter_rate
    supported = dataclasses.replace(info, window_s=check.used)
    return supported, clutter_rate * clutter_exposure(record, info) / clutter_exposure(record, supported)
