"""The array's table values judged on the whole mission: each source's offset, drift and
position against what every float's arrivals together support.

The array fit's posterior of theta, N(theta, S^-1), has every float's own unknowns (nodes,
clocks, mean current) already eliminated (`schur`): a float's clock error is its own, and
only a source's values shared by all its floats are left. As a float's checks do
(`calibrate.metadata_checks`), a value's prior is taken out of its marginal to give the
arrivals' own estimate (`data_only`), judged by the same rule (`outcome_of`: contradicted
beyond `[checks] mission_z_score` sds and the value's tolerance; consistent within it; else
undetermined), its sd widened to the floats' jackknife spread where that is wider
(`widening`). Per source, the offset at the table's epoch (o = a - d mid) and the drift
from the joint estimate of (a, d), and its clock over the mission (`clock_check`: a alone,
the correction at the arrivals' mean time, where it is nearly uncorrelated with d: decided
even where the mission cannot split it between offset and drift); the position from that
of (east, north, a, d), judged along the displacement (a displacement along every float's
bearing is an offset: only floats heard from several bearings decide it). A source heard on
fewer than `MIN_SOURCE_ARRIVALS` weighted arrivals in all is not judged.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..calibrate.metadata_checks import (
    CONTRADICTED,
    MIN_SOURCE_ARRIVALS,
    UNDETERMINED,
    MetadataCheck,
    beacon_source,
    data_only,
    outcome_of,
    shift_check,
    source_timing_checks,
    z_of,
)
from ..config import ChecksConfig
from ..domain import BeaconTable
from .array_fit import ArrayFit, floats_weighing

CLOCK = "clock_s"  # a source's clock over the mission (`clock_check`): not a table column
TIMING = ("offset_s", "drift_s_per_day", CLOCK)
# The theta blocks (`array_fit.SOURCE_BLOCKS`) a field's release frees.
RELEASES = {"offset_s": (0,), "drift_s_per_day": (1,), CLOCK: (0,), "position": (3, 4)}
# Corrections beyond these are no estimate: the linearised model does not reach so far (a
# source's range is linear in its displacement d only while d^2 / 2R stays small: 5 km at
# 1000 km for d = 100 km), or the floats' labels were not the source's. Such a value is
# undetermined, never written into the calibrated table.
PLAUSIBLE = {"offset_s": 1000.0, "drift_s_per_day": 0.2, CLOCK: 1000.0, "position": 100.0}


@dataclass(frozen=True)
class ArrayValue:
    """One source's value judged on the mission: the check, and the floats and weighted
    arrivals it rests on."""

    check: MetadataCheck
    source: int  # position in the array's sources
    floats: int
    arrivals: float


def support(fit: ArrayFit) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """(G,) per source the floats whose arrivals of it weigh in the fit (not those whose
    arrivals of it were all set aside or given weight 0) and the weight of their arrivals."""
    arrivals = np.zeros(len(fit.layout.sources))
    for f, w in zip(fit.floats, fit.weight, strict=True):
        np.add.at(arrivals, fit.layout.arrival_sources(f), w)
    return floats_weighing(fit.layout, fit.floats, fit.weight), arrivals


def _block(fit: ArrayFit, source: int, blocks: tuple[int, ...], widen: bool) -> tuple[NDArray, NDArray] | None:
    """The arrivals' own estimate (mean, covariance) of a source's unknowns in `blocks`;
    with `widen`, each sd widened to the floats' spread where that is wider (`widening`)."""
    idx = fit.layout.column(np.array(blocks), source)
    found = data_only(fit.theta[idx], fit.covariance[np.ix_(idx, idx)], fit.priors.sd()[idx])
    if found is None or not widen:
        return found
    mean, cov = found
    factor = widening(fit, idx)
    return mean, cov * np.outer(factor, factor)


def widening(fit: ArrayFit, idx: NDArray[np.intp]) -> NDArray[np.float64]:
    """Per unknown, max(1, jackknife sd / posterior sd): how much wider the floats' spread
    of the estimate is than the arrivals' noise says (`schur`: the floats, not the arrivals,
    are independent). On the stress missions the posterior sds alone put the estimates of
    correct values 3-13 sd from the truth, the widened ones within 2.5 (docs/decisions.md)."""
    posterior = np.diag(fit.covariance)[idx]
    spread = np.diag(fit.jackknife)[idx]
    return np.maximum(1.0, np.sqrt(spread / np.maximum(posterior, np.finfo(float).tiny)))


def plausible(check: MetadataCheck) -> MetadataCheck:
    """`check`, undetermined where its correction lies beyond `PLAUSIBLE`."""
    if check.supported is None or check.given is None or isinstance(check.supported, str):
        return check
    shift = float(check.supported) - (0.0 if check.field == "position" else float(check.given))  # type: ignore[arg-type]
    if abs(shift) <= PLAUSIBLE[check.field]:
        return check
    return dataclasses.replace(check, outcome=UNDETERMINED, note="beyond what the linearised fit can estimate")


def clock_check(
    beacons: BeaconTable, row: int, arrivals: tuple[NDArray, NDArray] | None, mid_day: float, checks: ChecksConfig
) -> MetadataCheck:
    """A source's clock over the mission: the table's offset + drift mid at the arrivals'
    mean time (`mid_day` days after its epoch) against the arrivals' estimate there, a of
    their joint estimate `arrivals` of (a, d) (undetermined without a value when None).

    At the mean time a and d are nearly uncorrelated: one mission-year of arrivals decides a
    source's clock to a second where its offset at the epoch (a - d mid) is uncertain by
    tens, the drift's uncertainty times the years since the epoch. Judged at a float's
    z-score (`checks.z_score`, which `array_values` passes), not the mission's: the most
    precise of a source's values, the clock is the most exposed to what the model lacks.
    On the held-out stress missions the right clocks lay up to 4.3 of their (widened) sds
    from the truth where the right offsets and drifts lay within 2.5 (docs/decisions.md)."""
    file, line, name = beacon_source(beacons, row)
    given = round(float(beacons.offset_s[row] + beacons.drift_s_per_day[row] * mid_day), 3)
    if arrivals is None:
        return MetadataCheck(file, line, name, CLOCK, given, None, None, "s", UNDETERMINED)
    correction, sd = float(arrivals[0][0]), float(np.sqrt(arrivals[1][0, 0]))
    outcome = outcome_of(correction, sd, checks.offset_tolerance_s, checks.z_score)
    return MetadataCheck(file, line, name, CLOCK, given, round(given + correction, 3), round(sd, 3), "s", outcome)


def array_values(fit: ArrayFit, beacons: BeaconTable, checks: ChecksConfig, widen: bool = True) -> list[ArrayValue]:
    """Every source's offset, drift, clock and position judged on the mission (module
    docstring; at `mission_z_score`, a clock at `z_score`), undetermined beyond `PLAUSIBLE`;
    `widen=False` judges by the arrivals' noise alone, as if every arrival were independent."""
    floats, arrivals = support(fit)
    mission = dataclasses.replace(checks, z_score=checks.mission_z_score)
    found = []
    for g, row in enumerate(fit.layout.sources):
        judged = arrivals[g] >= MIN_SOURCE_ARRIVALS
        timing_joint = _block(fit, g, (0, 1), widen) if judged else None
        mid = float(fit.layout.mid_days[g])
        timing = [*source_timing_checks(beacons, int(row), timing_joint, mid, mission),
                  clock_check(beacons, int(row), timing_joint, mid, checks)]  # fmt: skip
        file, line, name = beacon_source(beacons, int(row))
        given = (float(beacons.lat[row]), float(beacons.lon[row]))
        joint = _block(fit, g, (3, 4, 0, 1), widen) if judged else None
        position = shift_check(
            file, line, name, "position", given, joint, mission.position_tolerance_km, mission.z_score
        )
        found += [ArrayValue(plausible(c), g, int(floats[g]), float(arrivals[g])) for c in (*timing, position)]
    return found


def open_contradictions(values: list[ArrayValue], released: NDArray[np.bool_]) -> list[ArrayValue]:
    """The contradicted values not yet released (`released` (G, 5) by theta block)."""
    return [v for v in values if v.check.outcome == CONTRADICTED and not released[v.source, RELEASES[v.check.field][0]]]


def strongest_contradiction(values: list[ArrayValue], released: NDArray[np.bool_]) -> ArrayValue | None:
    """The contradicted value farthest from its table value in its sds, of those not yet
    released (`released` (G, 5) by theta block); None when there is none."""
    return max(open_contradictions(values, released), key=lambda v: z_of(v.check), default=None)
