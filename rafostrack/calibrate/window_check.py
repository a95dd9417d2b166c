"""The float's listening window (floats.csv window_s) against its arrivals.

Too short: the reader drops the TOAs later than window_s (`ArrivalRecord.late_toa_s`). At
least `MIN_LATE_TOAS` of them say the float listened longer (one or two are more likely
corrupt entries than a wrong window): contradicted, the arrivals support the latest of
them. The track keeps the given window (the TOAs past it are no longer in the record), and
the warning asks for the window the float listened.

Too long: a window that stored fewer than max_signals TOAs was listened to its end, and
the model spreads clutter uniformly over it. At the calibrated rate lambda per window, the
clutter of the n such windows falls past the record's latest TOA T as a Poisson count of
mean

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

The windows are short against the float's drift, so a window somewhat too long or too
short changes a track little (docs/decisions.md); the check is there for gross errors.
"""

from __future__ import annotations

import dataclasses
import math

from scipy.special import log_ndtr

from ..domain import ArrivalRecord, FloatInfo
from .metadata_checks import CONSISTENT, CONTRADICTED, UNDETERMINED, MetadataCheck, float_source
from .noise import clutter_exposure

MIN_LATE_TOAS = 3
CONSISTENT_MU = -math.log(0.05)
FIELD = "window_s"
TOO_SHORT_NOTE = "its TOAs past the window were dropped when read: give the window the float listened and track again"


def window_check(record: ArrivalRecord, info: FloatInfo, clutter_rate: float, z: float) -> MetadataCheck:
    """`info.window_s` against the arrivals of `record`, at `clutter_rate` signals per
    window (module docstring)."""
    file, line = float_source(info)
    given = float(info.window_s)

    def check(supported: float | None, outcome: str, note: str | None = None) -> MetadataCheck:
        used = supported if outcome == CONTRADICTED and note is None else given
        return MetadataCheck(file, line, info.float_id, FIELD, given, supported, None, "s", outcome, used=used,
                             note=note)  # fmt: skip

    if len(record.late_toa_s) >= MIN_LATE_TOAS:
        return check(float(math.ceil(max(record.late_toa_s))), CONTRADICTED, TOO_SHORT_NOTE)
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
