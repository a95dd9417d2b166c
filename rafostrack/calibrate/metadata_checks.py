"""The table values weighed against the arrivals: is each value in floats.csv and beacons.csv
that calibration uses what the arrivals support?

The timing fit (`calibrate.kalman`) treats each table value as a measurement: the launch and
end fixes (position offsets x ~ N(0, sd^2 I) at the first and last nodes), the float clock's
offsets (the clock residual c ~ N(0, `[fixes] clock_offset_sd_s`^2) at launch and at the
end), each heard source's offset and drift corrections (a_i, d_i ~ N(0, diag(p_a^2,
p_d^2))). Its posterior of such a value's correction x, N(m, C), holds the prior N(0, P) and
the arrivals; the arrivals' own estimate follows by taking the prior out, exactly for the
linearised Gaussian model (the prior enters only x's block of the information matrix, so of
x's marginal information too):

    C_d^-1 = C^-1 - P^-1,    m_d = C_d C^-1 m.

A value is *contradicted* when the arrivals' correction lies farther from zero than
`[checks] z_score` (the launch fix: `launch_z_score`) of its standard deviations,
z sqrt(C_d) (the arrivals are sure the value is not the table's), and than the value's
tolerance (the difference matters; the prior's own width, which lets calibration refine a
value, is not an error); *consistent* when the arrivals place it within the tolerance,
|correction| <= tolerance + 2 sd with sd <= tolerance (their 95% interval reaches the
tolerance band); *undetermined* otherwise: the arrivals' sd exceeds the tolerance (or
C_d^-1 is not positive: the arrivals alone do not fix it), or they lean away from the value
without being sure of it, or the source is heard on fewer than `MIN_SOURCE_ARRIVALS` of the
fit's arrivals (then without a value). A value the table does not give (an empty
clock_offset_end_s) is *estimated*, or undetermined when its sd exceeds the tolerance (then
with a warning: the track rests on a value the data cannot check); without an end fix, it is
the clock's offset at the last window the arrivals label surely (the check's `note` says when). What calibration does
with a contradicted value (tracks with the arrivals' value) is `calibrate.release`'s.

The check of one value (`MetadataCheck`), its outcome (`outcome_of`) and its warning are
`value_check`'s; this module computes the checks from the timing fit. The names of
`value_check` stay importable from here, where most callers import them.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..config import ChecksConfig
from ..domain import BeaconTable, FloatInfo
from ..model.geodesy import displace
from . import kalman
from .kalman_evidence import solved
from .kalman_problem import CLOCK, NODE, position_prior_sd, timing_prior_sd
from .value_check import (
    CONSISTENT,
    CONTRADICTED,
    ESTIMATED,
    SCHEDULE_FIELDS,
    SOURCE_UNKNOWNS,
    TOLERANCE_SETTING,
    TRACKED_WITH_SUPPORTED,
    UNDETERMINED,
    MetadataCheck,
    SourceInformation,
    beacon_source,
    float_source,
    outcome_of,
    undecided_note,
    warnings_of,
    z_of,
)

__all__ = [
    "CONSISTENT",
    "CONTRADICTED",
    "ESTIMATED",
    "MIN_SOURCE_ARRIVALS",
    "SCHEDULE_FIELDS",
    "SOURCE_UNKNOWNS",
    "TOLERANCE_SETTING",
    "TRACKED_WITH_SUPPORTED",
    "UNDETERMINED",
    "MetadataCheck",
    "SourceInformation",
    "along_itself",
    "beacon_source",
    "data_only",
    "float_source",
    "outcome_of",
    "position_checks",
    "shift_check",
    "source_information",
    "source_timing_checks",
    "timing_checks",
    "undecided_note",
    "warnings_of",
    "with_position_alternative",
    "z_of",
]

# A source on fewer confident arrivals than this is not judged (its checks undetermined,
# without a value): the checks' sds hold only if the labels are right, and a source heard
# a handful of times in a record is most often clutter that fell near its predicted times.
MIN_SOURCE_ARRIVALS = 10


def data_only(mean: NDArray, cov: NDArray, prior_sd: NDArray) -> tuple[NDArray, NDArray] | None:
    """The arrivals' estimate of a correction x whose posterior N(mean, cov) holds the prior
    N(0, diag(prior_sd^2)): C_d^-1 = C^-1 - P^-1, m_d = C_d C^-1 m (module docstring); None
    when C_d^-1 is not positive definite (the arrivals alone do not determine x)."""
    info = np.linalg.inv(cov)
    info_d = info - np.diag(1.0 / np.asarray(prior_sd, dtype=float) ** 2)
    info_d = 0.5 * (info_d + info_d.T)
    if np.linalg.eigvalsh(info_d).min() <= 1e-12 * max(1.0, float(np.abs(info).max())):
        return None
    cov_d = np.linalg.inv(info_d)
    return cov_d @ info @ mean, cov_d


@dataclass(frozen=True)
class _Posterior:
    """The timing fit's posterior over chosen unknowns: mean and covariance by index."""

    mean: NDArray[np.float64]  # (n_unknowns,)
    columns: NDArray[np.intp]
    cov_columns: NDArray[np.float64]  # (n_unknowns, len(columns)): N^-1 [:, columns]

    @classmethod
    def of(
        cls,
        problem: kalman.Problem,
        unknowns: NDArray,
        fit: kalman.KalmanFit,
        priors: kalman.KalmanPriors,
        columns: NDArray,
    ) -> _Posterior:
        """One Gauss-Newton step of `problem` from `unknowns` (the fit's weights and
        hyperparameters): the solution and the covariance columns of `columns`."""
        lin = kalman.linearise(problem, unknowns, fit.weight, priors)
        _, factor, step = solved(lin, fit.hyper)
        rhs = np.zeros((problem.n_unknowns, len(columns)))
        rhs[columns, np.arange(len(columns))] = 1.0
        return cls(unknowns + step, np.asarray(columns), factor.solve(rhs))

    def block(self, idx: list[int] | NDArray) -> tuple[NDArray, NDArray]:
        at = [int(np.flatnonzero(self.columns == i)[0]) for i in idx]
        return self.mean[list(idx)], self.cov_columns[np.ix_(list(idx), at)]


def timing_checks(
    problem: kalman.Problem,
    fit: kalman.KalmanFit,
    priors: kalman.KalmanPriors,
    heard: NDArray[np.intp],
    mid_days: NDArray[np.float64],
    beacons: BeaconTable,
    info: FloatInfo,
    checks: ChecksConfig,
) -> list[MetadataCheck]:
    """Every table value in the timing fit against the arrivals: the fixes, the float clock's
    offsets, each heard source's offset and drift (module docstring)."""
    last = problem.n_nodes - 1
    columns = [0, 1, CLOCK, NODE * last, NODE * last + 1, NODE * last + CLOCK]
    columns += [*problem.per_beacon(0), *problem.per_beacon(1)]
    post = _Posterior.of(problem, fit.unknowns, fit, priors, np.array(sorted(set(columns))))
    found = _fix_checks(problem, post, info, checks) + _clock_checks(problem, post, info, checks)
    timing = _source_checks(problem, post, priors, heard, mid_days, beacons, checks)
    positions = position_checks(problem, fit, priors, heard, mid_days, beacons, checks)
    return found + with_position_alternative(timing, positions)


def with_position_alternative(timing: list[MetadataCheck], positions: list[MetadataCheck]) -> list[MetadataCheck]:
    """`timing` and `positions`, a contradicted offset or drift of a source whose position
    the arrivals cannot check naming the position as the other explanation: a source
    displaced by d moves its arrivals by -u.d / c, u the unit vector towards the float,
    which is a constant (an offset) while the float's bearing holds and a trend (a drift)
    while it turns steadily."""
    unchecked = {p.id for p in positions if p.outcome == UNDETERMINED}
    timing = [
        dataclasses.replace(c, alternatives=("position",)) if c.outcome == CONTRADICTED and c.id in unchecked else c
        for c in timing
    ]
    return timing + positions


def _clock_index(problem: kalman.Problem) -> list[int]:
    """The clock residual's unknowns at launch and at the last node."""
    return [CLOCK, NODE * (problem.n_nodes - 1) + CLOCK]


def _clock_sd(problem: kalman.Problem) -> list[float]:
    """Their priors' sds (infinite: no prior, at an end the table leaves out or without an
    end fix)."""
    start_sd, end_sd = problem.clock_sd_s
    return [start_sd, np.inf if end_sd is None or problem.end_sd_km is None else end_sd]


def _fix_checks(
    problem: kalman.Problem, post: _Posterior, info: FloatInfo, checks: ChecksConfig
) -> list[MetadataCheck]:
    """The launch fix (first node) and, when used, the end fix (last node)."""
    file, line = float_source(info)
    launch, end = [0, 1], [NODE * (problem.n_nodes - 1), NODE * (problem.n_nodes - 1) + 1]
    fixes = [("launch_fix", 0, launch, [problem.launch_sd_km] * 2, checks.launch_z_score)]
    if problem.end_sd_km is not None:
        fixes.append(("end_fix", problem.n_nodes - 1, end, [problem.end_sd_km] * 2, checks.z_score))
    found = []
    for name, node, index, prior_sd, z_score in fixes:
        arrivals = data_only(*post.block(index), np.array(prior_sd))
        given = (float(problem.lat[node]), float(problem.lon[node]))
        found.append(shift_check(file, line, info.float_id, name, given, arrivals, checks.fix_tolerance_km, z_score))
    return found


def shift_check(
    file: str,
    line: int | None,
    id_: str,
    field: str,
    given: tuple[float, float],
    arrivals: tuple[NDArray, NDArray] | None,
    tolerance_km: float,
    z_score: float,
) -> MetadataCheck:
    """A position (a fix, a source) against the arrivals' estimate of its displacement (east,
    north km: the first two of `arrivals`' mean and covariance), judged along its direction."""
    if arrivals is None:
        return MetadataCheck(file, line, id_, field, 0.0, None, None, "km", UNDETERMINED, given_lat_lon=given)
    shift, cov = arrivals[0][:2], arrivals[1][:2, :2]
    distance, sd = along_itself(shift, cov)
    outcome = outcome_of(distance, sd, tolerance_km, z_score)
    lat, lon = displace(np.array(given[0]), np.array(given[1]), shift[0], shift[1])
    supported = (round(float(lat), 4), round(float(lon), 4))
    return MetadataCheck(file, line, id_, field, 0.0, round(distance, 2), round(sd, 2), "km", outcome,
                         given_lat_lon=given, supported_lat_lon=supported)  # fmt: skip


def along_itself(shift_km: NDArray, cov_km2: NDArray) -> tuple[float, float]:
    """A displacement's length and its sd along its own direction (east if it is 0)."""
    distance = float(np.hypot(*shift_km))
    direction = shift_km / distance if distance > 0 else np.array([1.0, 0.0])
    return distance, float(np.sqrt(direction @ cov_km2 @ direction))


def _clock_checks(
    problem: kalman.Problem, post: _Posterior, info: FloatInfo, checks: ChecksConfig
) -> list[MetadataCheck]:
    """The clock's offsets at launch and at the end fix. The arrivals fix the clock's drift
    between them well and its level only as well as the sources' offsets allow, so the launch
    offset is checked through the level (both offsets' priors taken out), the end offset
    through the drift since launch (the launch offset taken as right unless its own check
    contradicts it); an end offset the table leaves out is estimated (without an end fix, at
    the last node: the last window the arrivals label surely)."""
    file, line = float_source(info)
    start_sd, end_sd = _clock_sd(problem)  # an end offset released by calibration: no prior (inf)
    last = NODE * (problem.n_nodes - 1) + CLOCK
    if problem.end_sd_km is None or not info.has_end_clock:
        start = _clock_level_check(post, [CLOCK], [start_sd], info, checks)
        if problem.end_sd_km is not None:
            return [start, _estimated_end_clock(post, last, info, checks)]
        if info.has_end_clock:
            return [start]
        stamp = np.datetime_as_string(problem.time[-1].astype("datetime64[s]")) + "Z"
        note = f"at {stamp}, the last window the arrivals label surely (there is no end fix)"
        return [start, dataclasses.replace(_estimated_end_clock(post, last, info, checks), note=note)]
    arrivals = data_only(*post.block([CLOCK, last]), np.array([start_sd, end_sd]))
    start = _clock_level_check(post, [CLOCK, last], [start_sd, end_sd], info, checks)
    if arrivals is None:
        end_check = MetadataCheck(file, line, info.float_id, "clock_offset_end_s", info.clock_offset_end_s, None, None,
                                  "s", UNDETERMINED)  # fmt: skip
        return [start, end_check]
    mean, cov = arrivals[0][:2], arrivals[1][:2, :2]
    weights = np.array([0.0, 1.0]) if start.outcome == CONTRADICTED else np.array([-1.0, 1.0])
    correction, sd_d = float(weights @ mean), float(np.sqrt(weights @ cov @ weights))
    outcome = outcome_of(correction, sd_d, checks.clock_tolerance_s, checks.z_score)
    end = info.clock_offset_end_s
    return [start, MetadataCheck(file, line, info.float_id, "clock_offset_end_s", end, round(end + correction, 3),
                                 round(sd_d, 3), "s", outcome)]  # fmt: skip


def _clock_level_check(
    post: _Posterior, index: list[int], prior_sd: list[float], info: FloatInfo, checks: ChecksConfig
) -> MetadataCheck:
    """The launch offset against the arrivals, the clock priors at `index` taken out."""
    file, line = float_source(info)
    given = info.clock_offset_start_s
    arrivals = data_only(*post.block(index), np.array(prior_sd))
    if arrivals is None:
        return MetadataCheck(file, line, info.float_id, "clock_offset_start_s", given, None, None, "s", UNDETERMINED)
    correction, sd_d = float(arrivals[0][0]), float(np.sqrt(arrivals[1][0, 0]))
    outcome = outcome_of(correction, sd_d, checks.clock_tolerance_s, checks.z_score)
    return MetadataCheck(file, line, info.float_id, "clock_offset_start_s", given, round(given + correction, 3),
                         round(sd_d, 3), "s", outcome)  # fmt: skip


def _estimated_end_clock(post: _Posterior, index: int, info: FloatInfo, checks: ChecksConfig) -> MetadataCheck:
    """The end offset that the table leaves out: the start offset plus the clock residual at
    the end fix; undetermined where its sd exceeds the tolerance."""
    file, line = float_source(info)
    mean, cov = post.block([index])
    sd = float(np.sqrt(cov[0, 0]))
    outcome = ESTIMATED if sd <= checks.clock_tolerance_s else UNDETERMINED
    supported = round(info.clock_offset_start_s + float(mean[0]), 3)
    return MetadataCheck(file, line, info.float_id, "clock_offset_end_s", None, supported, round(sd, 3), "s", outcome)


def _source_checks(
    problem: kalman.Problem,
    post: _Posterior,
    priors: kalman.KalmanPriors,
    heard: NDArray[np.intp],
    mid_days: NDArray[np.float64],
    beacons: BeaconTable,
    checks: ChecksConfig,
) -> list[MetadataCheck]:
    """Each heard source's offset (at its epoch: a_i - d_i mid_i) and drift, from the
    arrivals' joint estimate of (a_i, d_i) and the clock offsets."""
    offset_sd, drift_sd = timing_prior_sd(problem, priors)
    judged = _judged_sources(problem)
    found = []
    for h, row in enumerate(heard):
        # The clock's priors out too: a wrong clock offset moves every source's arrivals alike,
        # which is the clock's to explain, not each source's.
        index = [problem.per_beacon(0)[h], problem.per_beacon(1)[h], *_clock_index(problem)]
        prior_sd = np.array([offset_sd[h], drift_sd[h], *_clock_sd(problem)])
        joint = data_only(*post.block(index), prior_sd) if judged[h] else None
        arrivals = None if joint is None else (joint[0][:2], joint[1][:2, :2])
        found += source_timing_checks(beacons, int(row), arrivals, float(mid_days[h]), checks)
    return found


def source_timing_checks(
    beacons: BeaconTable, row: int, arrivals: tuple[NDArray, NDArray] | None, mid_day: float, checks: ChecksConfig
) -> list[MetadataCheck]:
    """A source's offset (at its epoch: o = a - d mid, `mid_day` days after it) and drift
    from the arrivals' joint estimate `arrivals` (mean, covariance) of its (a, d)
    corrections; undetermined without a value when None."""
    file, line, name = beacon_source(beacons, row)
    values = (
        ("offset_s", float(beacons.offset_s[row]), np.array([1.0, -mid_day]), checks.offset_tolerance_s, "s"),
        ("drift_s_per_day", float(beacons.drift_s_per_day[row]), np.array([0.0, 1.0]),
         checks.drift_tolerance_s_per_day, "s/day"),
    )  # fmt: skip
    found = []
    for field, given, weights, tolerance, unit in values:
        if arrivals is None:
            found.append(MetadataCheck(file, line, name, field, given, None, None, unit, UNDETERMINED))
            continue
        correction = float(weights @ arrivals[0])
        sd_d = float(np.sqrt(weights @ arrivals[1] @ weights))
        outcome = outcome_of(correction, sd_d, tolerance, checks.z_score)
        digits = 3 if unit == "s" else 5
        found.append(MetadataCheck(file, line, name, field, given, round(given + correction, digits),
                                   round(sd_d, digits), unit, outcome))  # fmt: skip
    return found


def _judged_sources(problem: kalman.Problem) -> NDArray[np.bool_]:
    """(H,) the heard sources with at least `MIN_SOURCE_ARRIVALS` arrivals in the fit."""
    return np.bincount(problem.beacon, minlength=problem.n_heard) >= MIN_SOURCE_ARRIVALS


def position_checks(
    problem: kalman.Problem,
    fit: kalman.KalmanFit,
    priors: kalman.KalmanPriors,
    heard: NDArray[np.intp],
    mid_days: NDArray[np.float64],
    beacons: BeaconTable,
    checks: ChecksConfig,
) -> list[MetadataCheck]:
    """Each heard source's position: the timing fit's problem with the sources' positions as
    unknowns too (`Problem.source_positions`), one Gauss-Newton step from the fit, and per
    source the arrivals' estimate of its displacement with the priors of its position,
    offset and drift taken out (a displacement along the float's bearing is an offset; one
    across it shows only as the bearing changes: a source heard from one direction is
    undetermined). Each check carries the arrivals' information on the source
    (`SourceInformation`), which floats heard from other bearings complete."""
    moved = dataclasses.replace(problem, source_positions=True)
    start = fit.unknowns if problem.source_positions else np.concatenate([fit.unknowns, np.zeros(2 * problem.n_heard)])
    clock = _clock_index(moved)
    columns = np.concatenate([*(moved.per_beacon(block) for block in (3, 4, 0, 1)), clock])
    post = _Posterior.of(moved, start, fit, priors, columns)
    position_sd = position_prior_sd(moved, priors)
    offset_sd, drift_sd = timing_prior_sd(moved, priors)
    judged = _judged_sources(moved)
    found = []
    for h, row in enumerate(heard):
        index = [moved.per_beacon(block)[h] for block in (3, 4, 0, 1)]
        prior_sd = np.array([position_sd[h], position_sd[h], offset_sd[h], drift_sd[h]])
        arrivals = data_only(*post.block(index), prior_sd) if judged[h] else None
        file, line, name = beacon_source(beacons, int(row))
        given = (float(beacons.lat[row]), float(beacons.lon[row]))
        check = shift_check(file, line, name, "position", given, arrivals, checks.position_tolerance_km, checks.z_score)
        if not judged[h]:
            found.append(check)
            continue
        at = (float(beacons.offset_s[row]), float(beacons.drift_s_per_day[row]))
        information = source_information(
            *post.block(index + clock), np.concatenate([prior_sd, _clock_sd(moved)]), float(mid_days[h]), at
        )
        found.append(dataclasses.replace(check, information=information))
    return found


def source_information(
    mean: NDArray, cov: NDArray, prior_sd: NDArray, mid_day: float, at: tuple[float, float]
) -> SourceInformation:
    """The arrivals' information (J, h) on a source's (east, north, offset at the epoch, drift)
    corrections from the table's offset and drift `at`, from the posterior N(mean, cov) of
    (east, north, a, d, clock offsets) under a zero-mean
    prior of sds `prior_sd` (`SourceInformation`): the prior's information taken out
    (its mean is 0, so h = C^-1 mean is the arrivals' alone), the clocks marginalised, and
    a (the offset at the float's mid-time, `mid_day` days from the epoch) mapped to the
    offset at the epoch, o = a - d mid: with x = T^-1 x', J' = T^-T J T^-1, h' = T^-T h."""
    info = np.linalg.inv(cov)
    info_vector = info @ mean
    info = info - np.diag(1.0 / np.asarray(prior_sd, dtype=float) ** 2)
    j_xx, j_xc, j_cc = info[:4, :4], info[:4, 4:], info[4:, 4:]
    through = j_xc @ np.linalg.pinv(0.5 * (j_cc + j_cc.T), rcond=1e-10, hermitian=True)
    matrix = j_xx - through @ j_xc.T
    vector = info_vector[:4] - through @ info_vector[4:]
    to_epoch_inv = np.eye(4)
    to_epoch_inv[2, 3] = mid_day  # a = o + d mid
    matrix = to_epoch_inv.T @ (0.5 * (matrix + matrix.T)) @ to_epoch_inv
    vector = to_epoch_inv.T @ vector
    return SourceInformation(tuple(tuple(float(v) for v in r) for r in matrix), tuple(float(v) for v in vector), at)
