"""The batch Kalman smoother's state-space problem (`calibrate.kalman`) and its assembly.

The unknowns u: per node k (launch, windows with labelled arrivals, end fix) the position
offset from the nominal track (east, north km), the velocity (km/day), the clock residual
(s) and its rate (s/day), `NODE` of them; then the static parameters (mean current, shared
slowness deviation, per heard beacon offset, drift and slowness deviation). Every term of
the model (arrivals, motion between nodes, priors, the end fix) is a group of whitened
residual rows with their sparse Jacobian (`Rows`), built at a linearisation point u
(`linearise`) and reduced to normal-equation terms (`Normal`) for the solver and the
evidence (`calibrate.kalman_evidence`).
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import sparse

from ..domain import elapsed_days
from ..model.geodesy import displace, local_offsets_km, range_m
from ..motion.ou import ou_axis_moments

# Unknowns per node: east, north (km), v_east, v_north (km/day), clock residual (s), its rate (s/day).
NODE = 6
VELOCITY, CLOCK, RATE = 2, 4, 5
LOG_2PI = float(np.log(2.0 * np.pi))


@dataclass(frozen=True)
class KalmanPriors:
    """Prior sds of the static parameters and of the clock where it was measured."""

    sound_speed_m_s: float = 20.0
    beacon_sound_speed_m_s: float = 2.0
    offset_s: float = 3.0
    drift_s_per_day: float = 0.01
    # A source whose offset or drift the metadata checks found contradicted by the arrivals
    # (`Problem.released`): its corrections are the data's, under these wide priors.
    released_offset_s: float = 300.0
    released_drift_s_per_day: float = 0.2
    source_position_km: float = 0.5  # per axis, where positions are unknowns (`Problem.source_positions`)
    released_position_km: float = 100.0
    clock_rate_s_per_day: float = 0.1  # of the clock residual's rate at launch
    mean_current_km_per_day: float = 20.0


@dataclass(frozen=True)
class Hyper:
    """The smoother's hyperparameters (fitted by maximum marginal likelihood)."""

    velocity_sd_km_per_day: float
    decorrelation_days: float
    toa_sigma_s: float
    clock_rate_sd_s_per_day: float  # q: the clock rate's random walk, s/day per sqrt(day)

    # Bounds of the search, per field (a shorter time scale than a day cannot be told from
    # position errors by daily windows).
    LOWER = (0.3, 0.5, 0.2, 1e-5)
    UPPER = (40.0, 60.0, 20.0, 0.3)
    # Weak log-normal priors (`log_hyperprior`): medians and sds of the natural logs.
    PRIOR_MEDIAN = (5.0, 5.0, 2.0, 0.01)
    PRIOR_LOG_SD = (1.5, 1.5, 1.0, 1.0)

    def vector(self) -> NDArray[np.float64]:
        return np.log(dataclasses.astuple(self))

    @classmethod
    def from_vector(cls, x: NDArray, lower: tuple[float, ...] = LOWER) -> Hyper:
        return cls(*np.clip(np.exp(x), lower, cls.UPPER).tolist())

    @classmethod
    def lower_with_clock_floor(cls, clock_rate_sd_s_per_day: float) -> tuple[float, ...]:
        """`LOWER` with the clock's q held at or above `clock_rate_sd_s_per_day`."""
        return (*cls.LOWER[:3], max(cls.LOWER[3], clock_rate_sd_s_per_day))


HYPER_FIELDS = tuple(f.name for f in dataclasses.fields(Hyper))


@dataclass(frozen=True)
class Problem:
    """What the smoother fits: the nodes (times, nominal positions, fixes) and the arrivals."""

    time: NDArray[np.datetime64]  # (K,) node times, ascending
    lat: NDArray[np.float64]  # (K,) nominal positions
    lon: NDArray[np.float64]
    launch_sd_km: float
    end_sd_km: float | None  # the last node is the end fix when given
    node: NDArray[np.intp]  # (J,) node of each arrival
    beacon: NDArray[np.intp]  # (J,) index among the heard beacons
    toa_s: NDArray[np.float64]
    delay_s: NDArray[np.float64]  # (J,) catalogue offset + drift + linear clock
    drift_days: NDArray[np.float64]  # (J,) days since the beacon's epoch, minus its mid-record value
    beacon_lat: NDArray[np.float64]  # (H,) heard beacons
    beacon_lon: NDArray[np.float64]
    slowness_s_per_m: float  # s0 = 1 / configured sound speed
    # The clock residual's prior sd where the clock was measured: at launch, and at the end
    # fix (None: the end offset was not measured, no row).
    clock_sd_s: tuple[float, float | None] = (0.5, 0.5)
    released: NDArray[np.bool_] | None = None  # (H,) sources under `KalmanPriors.released_*`
    # The heard sources' positions as unknowns too (east, north km from the table's, under
    # `KalmanPriors.source_position_km`, or `released_position_km` for the sources in
    # `released_positions`): for the metadata checks, and for a fit that moves a source.
    source_positions: bool = False
    released_positions: NDArray[np.bool_] | None = None  # (H,)

    @property
    def n_nodes(self) -> int:
        return len(self.time)

    @property
    def n_heard(self) -> int:
        return len(self.beacon_lat)

    @property
    def n_unknowns(self) -> int:
        return NODE * self.n_nodes + 3 + (5 if self.source_positions else 3) * self.n_heard

    # Static unknowns after the nodes: vbar (2), ds, then a_i, d_i, ds_i per heard beacon.
    @property
    def vbar(self) -> int:
        """Index of the mean current's east component (north follows)."""
        return NODE * self.n_nodes

    @property
    def ds(self) -> int:
        return NODE * self.n_nodes + 2

    def per_beacon(self, block: int) -> NDArray[np.intp]:
        """Indices of the per-beacon unknowns: block 0 = a_i, 1 = d_i, 2 = ds_i, and with
        `source_positions` 3 = the source's east, 4 = its north displacement (km)."""
        return NODE * self.n_nodes + 3 + block * self.n_heard + np.arange(self.n_heard)


@dataclass(frozen=True)
class Block:
    """Rows with the same number e of Jacobian entries: whitened residuals (m,), and each
    row's entries as columns and values (m, e)."""

    residual: NDArray[np.float64]
    cols: NDArray[np.intp]
    vals: NDArray[np.float64]


@dataclass
class Rows:
    """Whitened residual rows r(u) with their sparse Jacobian, and log|W| of the whitening."""

    blocks: list[Block] = dataclasses.field(default_factory=list)
    log_whitening: float = 0.0
    n: int = 0

    def add(self, residual: NDArray, entries: list[tuple[NDArray, NDArray]], log_whitening: float) -> None:
        """Rows with whitened residuals `residual` (m,) and Jacobian entries, each a pair
        (columns (m,), values (m,)): one nonzero per row per pair."""
        m = len(residual)
        cols, vals = np.empty((m, len(entries)), dtype=np.intp), np.empty((m, len(entries)))
        for a, (col, val) in enumerate(entries):  # each broadcast to the rows
            cols[:, a], vals[:, a] = col, val
        self.blocks.append(Block(np.asarray(residual, dtype=float), cols, vals))
        self.log_whitening += log_whitening
        self.n += m

    def system(self, n_unknowns: int) -> tuple[sparse.csr_matrix, NDArray[np.float64]]:
        starts = np.cumsum([0] + [len(b.residual) for b in self.blocks])[:-1]
        rows = [
            np.repeat(start + np.arange(len(b.residual)), b.cols.shape[1])
            for start, b in zip(starts, self.blocks, strict=True)
        ]
        jac = sparse.csr_matrix(
            (
                np.concatenate([b.vals.ravel() for b in self.blocks]),
                (np.concatenate(rows), np.concatenate([b.cols.ravel() for b in self.blocks])),
            ),
            shape=(self.n, n_unknowns),
        )
        return jac, np.concatenate([b.residual for b in self.blocks])

    def stacked(self) -> Block:
        """All rows as one block, each row's entries padded to the widest row's with column
        -1 and value 0 (`BorderedBanded.inverse_times_rows`)."""
        width = max(b.cols.shape[1] for b in self.blocks)
        cols = np.full((self.n, width), -1, dtype=np.intp)
        vals = np.zeros((self.n, width))
        start = 0
        for b in self.blocks:
            m, e = b.cols.shape
            cols[start : start + m, :e] = b.cols
            vals[start : start + m, :e] = b.vals
            start += m
        return Block(np.concatenate([b.residual for b in self.blocks]), cols, vals)


def node_positions(problem: Problem, u: NDArray) -> tuple[NDArray, NDArray]:
    k = np.arange(problem.n_nodes)
    return displace(problem.lat, problem.lon, u[NODE * k], u[NODE * k + 1])


def _measurements(problem: Problem, u: NDArray, weight: NDArray, rows: Rows) -> NDArray:
    """Arrival rows whitened by sqrt(w) only (the 1 / sigma comes with the hyperparameters);
    returns the residuals (observed - predicted, s)."""
    k, i = problem.node, problem.beacon
    lat, lon = node_positions(problem, u)
    at_lat, at_lon = lat[k], lon[k]
    blat, blon = problem.beacon_lat[i], problem.beacon_lon[i]
    r = range_m(at_lat, at_lon, blat, blon)
    step = 0.1  # km, central differences of the range (m per km east / north)
    grad_e = (range_m(*displace(at_lat, at_lon, step, 0.0), blat, blon)
              - range_m(*displace(at_lat, at_lon, -step, 0.0), blat, blon)) / (2 * step)  # fmt: skip
    grad_n = (range_m(*displace(at_lat, at_lon, 0.0, step), blat, blon)
              - range_m(*displace(at_lat, at_lon, 0.0, -step), blat, blon)) / (2 * step)  # fmt: skip
    offsets, drifts, slownesses = (problem.per_beacon(block)[i] for block in range(3))
    slow = problem.slowness_s_per_m + u[problem.ds] + u[slownesses]
    a, d = u[offsets], u[drifts]
    source_entries: list[tuple[NDArray, NDArray]] = []
    if problem.source_positions:
        r, source_entries = _moved_source_ranges(problem, u, at_lat, at_lon, slow)
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


def _moved_source_ranges(
    problem: Problem, u: NDArray, at_lat: NDArray, at_lon: NDArray, slow: NDArray
) -> tuple[NDArray, list[tuple[NDArray, NDArray]]]:
    """Ranges (m) from the arrivals' nodes to their sources displaced by their position
    unknowns, and those unknowns' Jacobian entries (s per km, central differences)."""
    i = problem.beacon
    east, north = problem.per_beacon(3)[i], problem.per_beacon(4)[i]
    blat, blon = displace(problem.beacon_lat[i], problem.beacon_lon[i], u[east], u[north])
    step = 0.1  # km
    entries = []
    for col, (de, dn) in ((east, (step, 0.0)), (north, (0.0, step))):
        ahead = range_m(at_lat, at_lon, *displace(blat, blon, de, dn))
        behind = range_m(at_lat, at_lon, *displace(blat, blon, -de, -dn))
        entries.append((col, (ahead - behind) / (2 * step) * slow))
    return range_m(at_lat, at_lon, blat, blon), entries


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


def _statics(problem: Problem, u: NDArray, priors: KalmanPriors, rows: Rows) -> None:
    """Priors of the static parameters (slowness sds from sound-speed sds: ds = -dc / c^2)."""
    s0 = problem.slowness_s_per_m
    offset_sd, drift_sd = timing_prior_sd(problem, priors)
    for idx, sd in (
        (np.array([problem.vbar, problem.vbar + 1]), priors.mean_current_km_per_day),
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


def timing_prior_sd(problem: Problem, priors: KalmanPriors) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(H,) each heard source's prior sd of its offset (s) and of its drift (s/day)."""
    released = np.zeros(problem.n_heard, dtype=bool) if problem.released is None else problem.released
    return (
        np.where(released, priors.released_offset_s, priors.offset_s),
        np.where(released, priors.released_drift_s_per_day, priors.drift_s_per_day),
    )


def position_prior_sd(problem: Problem, priors: KalmanPriors) -> NDArray[np.float64]:
    """(H,) the prior sd of each heard source's position, per axis (km)."""
    released = np.zeros(problem.n_heard, bool) if problem.released_positions is None else problem.released_positions
    return np.where(released, priors.released_position_km, priors.source_position_km)


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
class Normal:
    """A group of rows reduced to its normal-equation terms: J'J, J'r, r'r and log|W|."""

    jtj: sparse.csr_matrix
    jtr: NDArray[np.float64]
    rtr: float
    log_whitening: float

    @classmethod
    def of(cls, rows: Rows, n_unknowns: int) -> Normal:
        return cls.of_system(*rows.system(n_unknowns), rows.log_whitening)

    @classmethod
    def of_system(cls, jac: sparse.csr_matrix, r: NDArray, log_whitening: float) -> Normal:
        return cls((jac.T @ jac).tocsr(), jac.T @ r, float(r @ r), log_whitening)


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


def linearise(problem: Problem, u: NDArray, weight: NDArray, priors: KalmanPriors) -> Linearised:
    arrivals = Rows()
    toa_residual = _measurements(problem, u, weight, arrivals)
    fixed = Rows()
    n_end = _end_fix(problem, u, fixed)
    _statics(problem, u, priors, fixed)
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
