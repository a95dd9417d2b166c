"""A mission's array calibrated: fitted on every float (`array_fit`), its values judged
(`array_checks`), the contradicted ones released one at a time and fitted again.

One at a time, the strongest first: under the tight priors of a source's values, a wrong
one pulls the fit, and with it the judgement of the others (an offset 25 s off leans on the
shared sound speed, which every other source then seems to contradict a little). Released,
its prior is wide (`KalmanPriors.released_*`) and its estimate the arrivals'; the others are
judged again without its pull. What is still contradicted after `MAX_RELEASES` is reported
so, and not corrected.

Each value is judged with its sd widened to the floats' spread where that is wider
(`array_checks.widening`): the floats, not their arrivals, are the mission's independent
units. A float that stands out among a source's floats (its left-out step an outlier among
theirs, the source's unknowns tested together: `array_fit.outlying_pairs`; its track or its
labels of that source are off) would pull the source's estimate and alone set its spread,
hiding what every other float agrees on; its arrivals of that source are set aside (weight
0) in the next fit, so that the estimate and its spread rest on the same floats. Not on a
source with a contradicted value, until one of its values is released: a wrong value makes
the floats that see it best differ the most (on a held-out mission, five floats' arrivals
of a source 30 s off were set aside, and the fault went undecided for two rounds). Once one
is released, the source's floats are tested: the others may be one float's pull (a float 40
s off on a source put its position 46 km off). Each fit after the first releases a value,
sets arrivals aside, or both; at most `MAX_RELEASES` releases, and `OUTLIER_PASSES` fits
that only set arrivals aside.

In a later round the floats were tracked with the values an earlier round decided: those
start released (`released_in`). Their tracks and labels fit those values, not the table's;
held at the table's under its tight prior, such a value is judged by extrapolating the
linearised fit from the wrong side (a position 38 km off, corrected in the tracking, was
estimated at 12, then at 103-125 km, as the other releases went by).

A source's timing is written as its clock over the mission (`array_checks.clock_check`):
where its offset, drift or clock is decided, the calibrated table's offset is the one that
puts the clock at the arrivals' value at their mean time, with the drift decided or as
given. The offset at the epoch (a - d mid) is what the arrivals judge, but written as such
with a drift they cannot decide it leaves the clock off over the mission by that drift's
error times the days since the epoch (12 s on a held-out mission, `docs/decisions.md`);
where neither the offset nor the drift is decided, a contradicted clock still is, and the
arrivals say how the clock is wrong over the mission, not how the error splits.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..calibrate import kalman
from ..calibrate.metadata_checks import CONTRADICTED, UNDETERMINED, MetadataCheck
from ..calibrate.release import SOURCE_FIELDS
from ..config import Config
from ..domain import BeaconTable
from ..model.geodesy import local_offsets_km
from .array_checks import (
    CLOCK,
    RELEASES,
    TIMING,
    ArrayValue,
    array_values,
    open_contradictions,
    strongest_contradiction,
)
from .array_fit import SOURCE_BLOCKS, ArrayFit, ArrayLayout, FloatMap, fit_array
from .floats import MissionFloat

TABLE_FIELDS = SOURCE_FIELDS  # the table's values a mission decides: a source's offset, drift, position
MAX_RELEASES = 12
RELEASE_ITERATIONS = 3  # Gauss-Newton steps after a release, from the previous fit
OUTLIER_PASSES = 3  # at most so many fits that only set outlying floats' arrivals aside
# A table within one sd of every decided value holds the mission's decisions: tracking again
# with a value moved by less than the arrivals can tell moves the floats by less than their
# own uncertainty. On the held-out faulted missions the values two rounds both decided moved
# 0.2-2.3 of their sds between them (their floats' labels differ; docs/decisions.md).
SETTLING_SD = 1.0
TRUSTED_RMS = 3.0
TRUSTED_SHARE = 0.25
UNTRUSTED_NOTE = "the floats do not fit one array (their tracks or labels are off)"


def local_distance_km(lat: NDArray, lon: NDArray, lat0: NDArray, lon0: NDArray) -> NDArray[np.float64]:
    """Distances (km) of positions from others nearby (tangent plane at the others)."""
    east, north = local_offsets_km(lat, lon, lat0, lon0)
    return np.hypot(east, north)


@dataclass(frozen=True)
class MissionArray:
    """The array fitted on a mission, its judged values and what was released."""

    fit: ArrayFit
    values: list[ArrayValue]
    released: NDArray[np.bool_]  # (G, 5) by source and theta block
    beacons: BeaconTable  # as given
    is_trusted: bool = True  # `trusted` at the configured TOA sd

    def _float_rms_s(self) -> NDArray[np.float64]:
        """Per float, the weighted rms of its arrival residuals at the fit."""
        return np.array([np.sqrt(np.sum(w * r**2) / max(float(np.sum(w)), 1.0))
                         for r, w in zip(self.fit.toa_residual_s, self.fit.weight, strict=True)])  # fmt: skip

    def floats_fitting(self, toa_sigma_s: float) -> NDArray[np.bool_]:
        """The floats whose weighted residuals at the fit lie within `TRUSTED_RMS` times the
        configured TOA sd (the others' tracks are lost, or their labels not the sources')."""
        return self._float_rms_s() <= TRUSTED_RMS * toa_sigma_s

    def rms_residual_s(self, toa_sigma_s: float) -> float:
        """The weighted rms of the fitting floats' arrival residuals at the fit (nan: none)."""
        fitting = self.floats_fitting(toa_sigma_s)
        if not fitting.any():
            return float("nan")
        r = np.concatenate([r for r, ok in zip(self.fit.toa_residual_s, fitting, strict=True) if ok])
        w = np.concatenate([w for w, ok in zip(self.fit.weight, fitting, strict=True) if ok])
        return float(np.sqrt(np.sum(w * r**2) / max(float(np.sum(w)), 1.0)))

    def trusted(self, toa_sigma_s: float) -> bool:
        """Whether the floats fit one array: at least `TRUSTED_SHARE` of them within
        `TRUSTED_RMS` times the configured TOA sd (floats whose tracks are lost, or labels
        not the sources', fit none; the mission then decides nothing)."""
        return bool(self.floats_fitting(toa_sigma_s).sum() >= max(1.0, TRUSTED_SHARE * len(self.fit.floats)))

    def decided(self) -> list[ArrayValue]:
        """The values the mission contradicts and estimates (released, fitted again); none
        when the fit is not `trusted`."""
        if not self.is_trusted:
            return []
        return [
            v
            for v in self.values
            if v.check.outcome == CONTRADICTED and self.released[v.source, RELEASES[v.check.field][0]]
        ]

    def calibrated_beacons(self) -> BeaconTable:
        """The table as given with only the decided values replaced by the mission's: a
        position moved; where a source's offset, drift or clock is decided, its clock over
        the mission put at the arrivals' value, with its drift theirs where that is decided
        and as given otherwise (module docstring)."""
        offset, drift = self.beacons.offset_s.copy(), self.beacons.drift_s_per_day.copy()
        lat, lon = self.beacons.lat.copy(), self.beacons.lon.copy()
        decided = self._decided_by_source()
        for g, fields in decided.items():
            row = int(self.fit.layout.sources[g])
            if "drift_s_per_day" in fields:
                drift[row] = float(fields["drift_s_per_day"].supported)  # type: ignore[arg-type]
            if any(field in fields for field in TIMING):
                clock = float(self._clock(g).supported)  # type: ignore[arg-type]
                offset[row] = clock - drift[row] * float(self.fit.layout.mid_days[g])
            position = fields.get("position")
            if position is not None and position.supported_lat_lon is not None:
                lat[row], lon[row] = position.supported_lat_lon
        return dataclasses.replace(self.beacons, offset_s=offset, drift_s_per_day=drift, lat=lat, lon=lon)

    def set_aside(self) -> list[str]:
        """Each float whose arrivals of a source the fit set aside, as "<float> <source>"."""
        ids = self.beacons.beacon_id
        return [f"{f.float_id} {ids[row]}" for f in self.fit.floats for row in f.set_aside]

    def _decided_by_source(self) -> dict[int, dict[str, MetadataCheck]]:
        """The decided values' checks by source (position in the array's) and field."""
        found: dict[int, dict[str, MetadataCheck]] = {}
        for v in self.decided():
            found.setdefault(v.source, {})[v.check.field] = v.check
        return found

    def _clock(self, source: int) -> MetadataCheck:
        """The source's `clock_s` check."""
        return next(v.check for v in self.values if v.source == source and v.check.field == CLOCK)

    def _decided_sds(self) -> dict[str, NDArray[np.float64]]:
        """Per table field (`TABLE_FIELDS`) and row, the sd of the decided value (an offset
        set by the clock moves with the clock and, where the drift is decided, the drift
        times the days to the mission), 0 where nothing was decided."""
        sds = {field: np.zeros(len(self.beacons)) for field in TABLE_FIELDS}
        for g, fields in self._decided_by_source().items():
            row = int(self.fit.layout.sources[g])
            rate = fields.get("drift_s_per_day")
            if rate is not None:
                sds["drift_s_per_day"][row] = float(rate.sd or 0.0)
            if any(field in fields for field in TIMING):
                drift_sd = 0.0 if rate is None else float(rate.sd or 0.0)
                mid = abs(float(self.fit.layout.mid_days[g]))
                sds["offset_s"][row] = float(self._clock(g).sd or 0.0) + mid * drift_sd
            if "position" in fields:
                sds["position"][row] = float(fields["position"].sd or 0.0)
        return sds

    def moved_sd(self, table: BeaconTable) -> float:
        """How far `table` (the one the floats were tracked with) lies from what the mission
        decides, in the decided values' sds: the largest |table - calibrated| / sd over the
        decided values; inf where a value not decided differs from the table as given, or
        the sources are not the same."""
        ours = self.calibrated_beacons()
        if len(table) != len(ours) or not np.array_equal(table.beacon_id, ours.beacon_id):
            return float("inf")
        moves = {
            "offset_s": np.abs(table.offset_s - ours.offset_s),
            "drift_s_per_day": np.abs(table.drift_s_per_day - ours.drift_s_per_day),
            "position": local_distance_km(table.lat, table.lon, ours.lat, ours.lon),
        }
        negligible = {"offset_s": 1e-9, "drift_s_per_day": 1e-12, "position": 1e-6}
        largest = 0.0
        for field, sd in self._decided_sds().items():
            moved = np.maximum(moves[field] - negligible[field], 0.0)
            with np.errstate(divide="ignore", invalid="ignore"):
                ratio = np.where(moved > 0, moved / sd, 0.0)
            largest = max(largest, float(np.max(ratio, initial=0.0)))
        return largest

    def settled_in(self, table: BeaconTable) -> bool:
        """Whether `table` (the one the floats were tracked with) already holds what the
        mission decides: each decided value within `SETTLING_SD` of its sd, every other as
        given (`moved_sd`)."""
        return self.moved_sd(table) <= SETTLING_SD


def array_priors(config: Config) -> kalman.KalmanPriors:
    """The array's priors; a sound speed the user set is held (1 mm/s), as a float's
    calibration holds it."""
    if ("model", "sound_speed_m_s") in config.explicit:
        return kalman.KalmanPriors(sound_speed_m_s=1e-3, beacon_sound_speed_m_s=1e-3)
    return kalman.DEFAULT_PRIORS


def changed_values(beacons: BeaconTable, table: BeaconTable) -> dict[str, NDArray[np.bool_]]:
    """Per table field (`TABLE_FIELDS`), the rows where `table` (made from `beacons`, with
    some cells changed) holds another value than `beacons`; none where its sources are not
    the same."""
    if not np.array_equal(table.beacon_id, beacons.beacon_id):
        return {field: np.zeros(len(beacons), dtype=bool) for field in TABLE_FIELDS}
    return {
        "offset_s": table.offset_s != beacons.offset_s,
        "drift_s_per_day": table.drift_s_per_day != beacons.drift_s_per_day,
        "position": (table.lat != beacons.lat) | (table.lon != beacons.lon),
    }


def released_in(layout: ArrayLayout, beacons: BeaconTable, tracked_with: BeaconTable | None) -> NDArray[np.bool_]:
    """(G, 5) by source and theta block: the values in which `tracked_with`, the table the
    floats were tracked with, differs from `beacons` as given (none without one)."""
    released = np.zeros((len(layout.sources), len(SOURCE_BLOCKS)), dtype=bool)
    if tracked_with is None:
        return released
    for field, moved in changed_values(beacons, tracked_with).items():
        for block in RELEASES[field]:
            released[:, block] |= moved[layout.sources]
    return released


def calibrated_array(
    floats: Sequence[MissionFloat],
    beacons: BeaconTable,
    config: Config,
    map_floats: FloatMap = map,
    tracked_with: BeaconTable | None = None,
) -> MissionArray:
    """Fit the array on `floats`, judge its values and release the contradicted ones one at
    a time, strongest first (module docstring), those the floats were tracked with
    (`tracked_with`, when not the table as given) released from the start; `map_floats`
    maps the fit's per-float work."""
    priors = array_priors(config)
    released = released_in(ArrayLayout.of(floats), beacons, tracked_with)
    fit = fit_array(floats, config, released, priors=priors, map_floats=map_floats)
    values = array_values(fit, beacons, config.checks)
    releases = passes = 0  # fits that released a value; fits that only set arrivals aside
    while True:
        worst = strongest_contradiction(values, released) if releases < MAX_RELEASES else None
        aside = _outlying_but_where_held(fit, values, released)
        if worst is None and (not aside or passes == OUTLIER_PASSES):
            break
        if worst is None:
            passes += 1
        else:
            released[worst.source, list(RELEASES[worst.check.field])] = True
            releases += 1
        start = dataclasses.replace(fit, floats=_set_aside(fit, aside), blocks=[]) if aside else fit
        fit = fit_array(
            start.floats, config, released, start=start, priors=priors, iterations=RELEASE_ITERATIONS,
            map_floats=map_floats,
        )  # fmt: skip
        values = array_values(fit, beacons, config.checks)
    array = MissionArray(dataclasses.replace(fit, blocks=[]), values, released, beacons)
    if array.trusted(config.model.toa_sigma_s):
        return array
    undecided = [dataclasses.replace(v, check=_untrusted(v.check)) for v in values]
    return dataclasses.replace(array, values=undecided, is_trusted=False)


def _outlying_but_where_held(
    fit: ArrayFit, values: list[ArrayValue], released: NDArray[np.bool_]
) -> list[tuple[int, int]]:
    """The fit's outlying (float, source) pairs (`ArrayFit.outlying`), none on a source held:
    one with a contradicted value and none released (module docstring)."""
    held = {v.source for v in open_contradictions(values, released) if not released[v.source].any()}
    return [(k, g) for k, g in fit.outlying if g not in held]


def _set_aside(fit: ArrayFit, pairs: list[tuple[int, int]]) -> list[MissionFloat]:
    """The fit's floats with each (float, source) pair's arrivals of `pairs` set aside."""
    floats = list(fit.floats)
    for k, g in pairs:
        aside = {*floats[k].set_aside, int(fit.layout.sources[g])}
        floats[k] = dataclasses.replace(floats[k], set_aside=tuple(sorted(aside)))
    return floats


def _untrusted(check: MetadataCheck) -> MetadataCheck:
    """A contradicted value of a fit the floats do not agree on: undetermined."""
    if check.outcome != CONTRADICTED:
        return check
    return dataclasses.replace(check, outcome=UNDETERMINED, note=UNTRUSTED_NOTE)


__all__ = ["MAX_RELEASES", "MissionArray", "array_priors", "calibrated_array", "changed_values", "released_in"]
