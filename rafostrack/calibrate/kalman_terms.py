"""The batch Kalman smoother's terms as whitened rows at a linearisation point u
(`linearise`): the arrivals, the motion between nodes, the static parameters' priors and the
end fix (`kalman_problem` gives the unknowns; `calibrate.kalman` fits them)."""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import sparse

from ..domain import elapsed_days
from ..model.geodesy import displace, local_offsets_km, range_of_terms_m, stacked_point_terms
from ..motion.ou import ou_axis_moments
from .kalman_problem import (
    CLOCK,
    NODE,
    RATE,
    VELOCITY,
    Hyper,
    KalmanPriors,
    Problem,
    node_positions,
    position_prior_sd,
    timing_prior_sd,
)
from .kalman_rows import Block, Normal, Rows


def _measurements(problem: Problem, u: NDArray, weight: NDArray, rows: Rows) -> NDArray:
    """Arrival rows whitened by sqrt(w) only (the 1 / sigma comes with the hyperparameters);
    returns the residuals (observed - predicted, s). The ranges' point terms are computed
    per node and per source and taken per arrival (`_arrival_terms`)."""
    k, i = problem.node, problem.beacon
    lat, lon = node_positions(problem, u)
    sources = stacked_point_terms(problem.beacon_lat, problem.beacon_lon)[:, i]

    def range_from(east_km: float, north_km: float) -> NDArray:
        return range_of_terms_m(_arrival_terms(lat, lon, k, east_km, north_km), sources)

    step = 0.1  # km, central differences of the range (m per km east / north)
    grad_e = (range_from(step, 0.0) - range_from(-step, 0.0)) / (2 * step)
    grad_n = (range_from(0.0, step) - range_from(0.0, -step)) / (2 * step)
    offsets, drifts, slownesses = (problem.per_beacon(block)[i] for block in range(3))
    slow = problem.slowness_s_per_m + u[problem.ds] + u[slownesses]
    a, d = u[offsets], u[drifts]
    at = _arrival_terms(lat, lon, k)
    source_entries: list[tuple[NDArray, NDArray]] = []
    if problem.source_positions:
        r, source_entries = _moved_source_ranges(problem, u, at, slow)
    else:
        r = range_of_terms_m(at, sources)
    predicted = problem.delay_s + a + d * problem.drift_days + u[NODE * k + CLOCK] + r * slow
    scale = np.sqrt(weight)
    resid = problem.toa_s - predicted
    rows.add(
        -scale * resid,  # whitened (predicted - observed)
        [
            (NODE * k, scale * grad_e * slow),
            (NODE * k + 1, scale * grad_n * slow),
            (NODE * k + CLOCK, scale),
            (np.asarray(problem.ds), scale * r),
            (slownesses, scale * r),
            (offsets, scale),
            (drifts, scale * problem.drift_days),
            *[(col, scale * value) for col, value in source_entries],
        ],
        # log sqrt(w): constant in the hyperparameters; rows of weight 0 (surely not the
        # direct path) carry no information and no term.
        float(np.sum(np.log(scale[scale > 0]))),
    )
    return resid


def _arrival_terms(
    lat: NDArray, lon: NDArray, index: NDArray[np.intp], east_km: float = 0.0, north_km: float = 0.0
) -> NDArray[np.float64]:
    """(6, J) the point terms (`stacked_point_terms`) of the points (lat, lon) taken at
    `index` (each arrival's node, or source), displaced by (east_km, north_km) unless both are
    0: computed on the points, fewer than the arrivals, then taken (every step elementwise:
    the same numbers as computed per arrival)."""
    if east_km == 0.0 and north_km == 0.0:  # not displaced: wrapping a longitude may round it
        return stacked_point_terms(lat, lon)[:, index]
    return stacked_point_terms(*displace(lat, lon, east_km, north_km))[:, index]


def _moved_source_ranges(
    problem: Problem, u: NDArray, at: NDArray, slow: NDArray
) -> tuple[NDArray, list[tuple[NDArray, NDArray]]]:
    """Ranges (m) from the arrivals' nodes (their point terms `at`) to their sources
    displaced by their position unknowns, and those unknowns' Jacobian entries (s per km,
    central differences)."""
    i = problem.beacon
    east, north = problem.per_beacon(3), problem.per_beacon(4)
    blat, blon = displace(problem.beacon_lat, problem.beacon_lon, u[east], u[north])
    step = 0.1  # km
    entries = []
    for col, (de, dn) in ((east[i], (step, 0.0)), (north[i], (0.0, step))):
        ahead = range_of_terms_m(at, _arrival_terms(blat, blon, i, de, dn))
        behind = range_of_terms_m(at, _arrival_terms(blat, blon, i, -de, -dn))
        entries.append((col, (ahead - behind) / (2 * step) * slow))
    return range_of_terms_m(at, _arrival_terms(blat, blon, i)), entries


def _pair_whitening(var_0: NDArray, cov: NDArray, var_1: NDArray) -> tuple[NDArray, NDArray, NDArray]:
    """W = L^-1 for L = chol([[var_0, cov], [cov, var_1]]), elementwise: (w11, w21, w22)."""
    l11 = np.sqrt(np.maximum(var_0, 1e-12))
    l21 = cov / l11
    l22 = np.sqrt(np.maximum(var_1 - l21 * l21, 1e-12))
    return 1.0 / l11, -l21 / (l11 * l22), 1.0 / l22


def _pair_rows(rows: Rows, e: tuple[NDArray, NDArray], de: tuple[list, list], moments: tuple) -> None:
    """Rows of one linear-Gaussian transition of a (level, rate) pair: errors e = (e_0, e_1)
    with Jacobian entries de = (entries of e_0, entries of e_1) and covariance moments
    (var_0, cov, var_1), whitened: rows w11 e_0 and w21 e_0 + w22 e_1."""
    w11, w21, w22 = _pair_whitening(*moments)
    d0, d1 = de
    rows.add(w11 * e[0], [(c, w11 * np.asarray(g)) for c, g in d0], float(np.sum(np.log(w11))))
    rows.add(
        w21 * e[0] + w22 * e[1],
        [(c, w21 * np.asarray(g)) for c, g in d0] + [(c, w22 * np.asarray(g)) for c, g in d1],
        float(np.sum(np.log(w22))),
    )


def _prior_row(rows: Rows, u: NDArray, col: int, sd: float, mean_col: int | None = None) -> None:
    """The row of a prior u[col] ~ N(u[mean_col] (or 0), sd^2)."""
    entries = [(np.array([col]), np.array([1.0 / sd]))]
    mean = 0.0
    if mean_col is not None:
        entries.append((np.array([mean_col]), np.array([-1.0 / sd])))
        mean = u[mean_col]
    rows.add(np.array([(u[col] - mean) / sd]), entries, -float(np.log(sd)))


def _motion(problem: Problem, u: NDArray, hyper: Hyper, priors: KalmanPriors, rows: Rows) -> None:
    """The transitions between nodes and the initial state: per axis the OU position and
    velocity, and the clock's integrated random walk (its rate a random walk of sd q per
    sqrt(day): Var = q^2 [[dt^3 / 3, dt^2 / 2], [dt^2 / 2, dt]]), each pair whitened by the
    inverse Cholesky factor of its 2x2 covariance."""
    days = elapsed_days(problem.time, problem.time[0])
    dt = np.diff(days)
    k = np.arange(problem.n_nodes - 1)
    n0, n1 = NODE * k, NODE * (k + 1)
    # Nominal displacement of node k+1 from node k, in k's tangent plane.
    nominal = local_offsets_km(problem.lat[1:], problem.lon[1:], problem.lat[:-1], problem.lon[:-1])
    vbar = problem.vbar
    sd, t = hyper.velocity_sd_km_per_day, hyper.decorrelation_days
    a, var_x, cov, var_v = ou_axis_moments(dt, sd, t)
    one_minus_a = 1.0 - a
    for axis in range(2):
        p0, p1, v0, v1, m = n0 + axis, n1 + axis, n0 + VELOCITY + axis, n1 + VELOCITY + axis, vbar + axis
        e_x = nominal[axis] + u[p1] - u[p0] - t * one_minus_a * u[v0] - (dt - t * one_minus_a) * u[m]
        e_v = u[v1] - a * u[v0] - one_minus_a * u[m]
        dx = [(p1, 1.0), (p0, -1.0), (v0, -t * one_minus_a), (m, -(dt - t * one_minus_a))]
        dv = [(v1, 1.0), (v0, -a), (m, -one_minus_a)]
        _pair_rows(rows, (e_x, e_v), (dx, dv), (var_x, cov, var_v))
    q2 = hyper.clock_rate_sd_s_per_day**2
    c0, c1, r0, r1 = n0 + CLOCK, n1 + CLOCK, n0 + RATE, n1 + RATE
    e_c = u[c1] - u[c0] - dt * u[r0]
    e_r = u[r1] - u[r0]
    _pair_rows(rows, (e_c, e_r), ([(c1, 1.0), (c0, -1.0), (r0, -dt)], [(r1, 1.0), (r0, -1.0)]),
               (q2 * dt**3 / 3.0, q2 * dt**2 / 2.0, q2 * dt))  # fmt: skip
    # Initial state: launch position, velocity about the mean current, clock measured at launch.
    for axis in range(2):
        _prior_row(rows, u, axis, problem.launch_sd_km)
        _prior_row(rows, u, VELOCITY + axis, sd, mean_col=vbar + axis)
    _prior_row(rows, u, CLOCK, problem.clock_sd_s[0])
    _prior_row(rows, u, RATE, priors.clock_rate_s_per_day)


def _statics(problem: Problem, u: NDArray, priors: KalmanPriors, rows: Rows, array_priors: bool) -> None:
    """Priors of the static parameters (slowness sds from sound-speed sds: ds = -dc / c^2);
    without `array_priors`, the float's own only (its mean current): a mission fit puts the
    array's priors in once (`rafostrack.mission`)."""
    own = (np.array([problem.vbar, problem.vbar + 1]), priors.mean_current_km_per_day)
    rows.add(u[own[0]] / own[1], [(own[0], np.full(2, 1 / own[1]))], -2.0 * float(np.log(own[1])))
    if not array_priors:
        return
    s0 = problem.slowness_s_per_m
    offset_sd, drift_sd = timing_prior_sd(problem, priors)
    for idx, sd in (
        (np.array([problem.ds]), priors.sound_speed_m_s * s0 * s0),
        (problem.per_beacon(0), offset_sd),
        (problem.per_beacon(1), drift_sd),
        (problem.per_beacon(2), priors.beacon_sound_speed_m_s * s0 * s0),
        *(
            [
                (problem.per_beacon(3), position_prior_sd(problem, priors)),
                (problem.per_beacon(4), position_prior_sd(problem, priors)),
            ]
            if problem.source_positions
            else []
        ),
    ):
        sds = np.broadcast_to(np.asarray(sd, dtype=float), idx.shape)
        rows.add(u[idx] / sds, [(idx, 1 / sds)], -float(np.sum(np.log(sds))))


def _end_fix(problem: Problem, u: NDArray, rows: Rows) -> int:
    """The end fix's rows (data): position and, where it was measured, the clock at the last
    node. Returns their count."""
    if problem.end_sd_km is None:
        return 0
    last = NODE * (problem.n_nodes - 1)
    for axis in range(2):
        _prior_row(rows, u, last + axis, problem.end_sd_km)
    end_clock_sd = problem.clock_sd_s[1]
    if end_clock_sd is None:
        return 2
    _prior_row(rows, u, last + CLOCK, end_clock_sd)
    return 3


@dataclass(frozen=True)
class Linearised:
    """The model linearised at one point u. The arrival rows (before their 1 / sigma), the
    end fix and the static priors do not depend on the hyperparameters: their normal terms
    are built once, and only the motion rows are rebuilt for each hyperparameter value."""

    problem: Problem
    u: NDArray[np.float64]
    arrival_rows: Rows  # at sigma = 1
    n_arrivals: int
    fixed: Normal
    n_data: int
    toa_residual_s: NDArray[np.float64]
    priors: KalmanPriors

    @functools.cached_property
    def arrival_system(self) -> tuple[sparse.csr_matrix, NDArray[np.float64]]:
        """The arrival rows' Jacobian and residuals (one row per arrival, at sigma = 1)."""
        return self.arrival_rows.system(self.problem.n_unknowns)

    @functools.cached_property
    def arrivals(self) -> Normal:
        """The arrival rows' normal terms (at sigma = 1)."""
        return Normal.of_system(*self.arrival_system, self.arrival_rows.log_whitening)

    @functools.cached_property
    def arrival_block(self) -> Block:
        return self.arrival_rows.stacked()

    def motion_rows(self, hyper: Hyper) -> Rows:
        rows = Rows()
        _motion(self.problem, self.u, hyper, self.priors, rows)
        return rows

    def normal(self, hyper: Hyper, motion_rows: Rows | None = None) -> Normal:
        """All rows' normal terms under `hyper` (its motion rows, when already built)."""
        rows = self.motion_rows(hyper) if motion_rows is None else motion_rows
        motion = Normal.of(rows, self.problem.n_unknowns)
        a, f, s2 = self.arrivals, self.fixed, hyper.toa_sigma_s**2
        return Normal(
            a.jtj / s2 + f.jtj + motion.jtj,
            a.jtr / s2 + f.jtr + motion.jtr,
            a.rtr / s2 + f.rtr + motion.rtr,
            a.log_whitening - self.n_arrivals * np.log(hyper.toa_sigma_s) + f.log_whitening + motion.log_whitening,
        )


def linearise(
    problem: Problem, u: NDArray, weight: NDArray, priors: KalmanPriors, *, array_priors: bool = True
) -> Linearised:
    """The model at u; without `array_priors` the sources' and the sound speed's priors are
    left out (`_statics`)."""
    arrivals = Rows()
    toa_residual = _measurements(problem, u, weight, arrivals)
    fixed = Rows()
    n_end = _end_fix(problem, u, fixed)
    _statics(problem, u, priors, fixed, array_priors)
    return Linearised(
        problem,
        u,
        arrivals,
        len(toa_residual),
        Normal.of(fixed, problem.n_unknowns),
        len(toa_residual) + n_end,
        toa_residual,
        priors,
    )
