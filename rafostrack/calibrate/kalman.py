"""The record's nuisances by a batch Kalman smoother: track, float clock and timing jointly.

Given arrivals whose source is known (the confident labels of a first pass), the float's
track and the parameters that shift arrival times form a linear-Gaussian state-space
model once the ranges are linearised about a nominal track (Chamberlain et al. 2023, RAFOS
tracking by Kalman smoothing, with the timing parameters in the state). Nodes k are the
launch, every window with labelled arrivals and the end fix; each carries

    s_k = (p_k, v_k, c_k): position offset from the nominal track (east/north km, in the
          nominal point's tangent plane), velocity (km/day) and the float-clock residual
          beyond the linear launch-to-end clock model (s),

with the motion of `motion.IntegratedOU` between nodes (the exact transition over the
interval: velocity sd sigma_v, decorrelation time T, mean current vbar) and a random walk
for the clock, c_{k+1} = c_k + N(0, q^2 dt). Static parameters theta: the mean current
vbar, the shared slowness deviation ds (1 / sound speed), and per heard beacon i an offset
a_i, a drift d_i (about the middle of its arrivals) and its own slowness deviation ds_i.
An arrival of beacon i at node k, its catalogue delay D (offset, drift, linear clock),

    T = D + a_i + d_i (days_i - mid_i) + c_k + R(p_k, b_i) (s0 + ds + ds_i) + e,
    e ~ N(0, sigma^2 / w),   w = P(direct path | residual)  (multipath, by EM),

and the fixes: p at launch ~ N(0, launch sd^2), p at the end observed with the end fix's
sd, the clock residual ~ N(0, 0.5 s) at both ends (where the clock was measured).

Every term is a whitened row of one sparse least-squares problem in all the unknowns
(the information form of the Kalman smoother: its solution is the RTS smoother's mean);
Gauss-Newton re-linearises the ranges. The hyperparameters h = (sigma_v, T, sigma, q) are
those maximising the marginal likelihood of the linearised model,

    log p(y | h) = -|r*|^2 / 2 - log|J'J| / 2 + sum log|W| - (n_data / 2) log 2 pi,

(r* the whitened residuals at the solution, J their Jacobian, W the rows' whitening), which
counts the parameters that the fit spends, unlike the residuals' own spread; the search
uses its gradient (`evidence_and_gradient`).

The posterior covariance also says what the nuisances leave undetermined: the position
variance that comes from the uncertain clock and timing parameters (law of total variance,
`nuisance_cov_km2`) is [N^-1]_pp - [N_xx^-1]_pp, N = J'J and N_xx its block of positions and
velocities. A particle filter run with the fitted values does not see it; the tracker adds
it to the filter's covariance.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pandas as pd
from numpy.typing import NDArray
from scipy import sparse
from scipy.optimize import minimize

from ..domain import elapsed_days
from ..geodesy import displace, local_offsets_km, range_m
from ..motion.ou import ou_axis_moments
from .banded import BorderedBanded

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
    clock_fix_s: float = 0.5
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

    @property
    def n_nodes(self) -> int:
        return len(self.time)

    @property
    def n_heard(self) -> int:
        return len(self.beacon_lat)

    @property
    def n_unknowns(self) -> int:
        return NODE * self.n_nodes + 3 + 3 * self.n_heard

    # Static unknowns after the nodes: vbar (2), ds, then a_i, d_i, ds_i per heard beacon.
    @property
    def vbar(self) -> int:
        """Index of the mean current's east component (north follows)."""
        return NODE * self.n_nodes

    @property
    def ds(self) -> int:
        return NODE * self.n_nodes + 2

    def per_beacon(self, block: int) -> NDArray[np.intp]:
        """Indices of the per-beacon unknowns: block 0 = a_i, 1 = d_i, 2 = ds_i."""
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
        cols = np.stack([np.broadcast_to(col, (m,)) for col, _ in entries], axis=1).astype(np.intp)
        vals = np.stack([np.broadcast_to(val, (m,)) for _, val in entries], axis=1).astype(float)
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


def _positions(problem: Problem, u: NDArray) -> tuple[NDArray, NDArray]:
    k = np.arange(problem.n_nodes)
    return displace(problem.lat, problem.lon, u[NODE * k], u[NODE * k + 1])


def _measurements(problem: Problem, u: NDArray, weight: NDArray, rows: Rows) -> NDArray:
    """Arrival rows whitened by sqrt(w) only (the 1 / sigma comes with the hyperparameters);
    returns the residuals (observed - predicted, s)."""
    k, i = problem.node, problem.beacon
    lat, lon = _positions(problem, u)
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
        ],
        # log sqrt(w): constant in the hyperparameters; rows of weight 0 (surely not the
        # direct path) carry no information and no term.
        float(np.sum(np.log(scale[scale > 0]))),
    )
    return resid


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
    _prior_row(rows, u, CLOCK, priors.clock_fix_s)
    _prior_row(rows, u, RATE, priors.clock_rate_s_per_day)


def _statics(problem: Problem, u: NDArray, priors: KalmanPriors, rows: Rows) -> None:
    """Priors of the static parameters (slowness sds from sound-speed sds: ds = -dc / c^2)."""
    s0 = problem.slowness_s_per_m
    for idx, sd in (
        (np.array([problem.vbar, problem.vbar + 1]), priors.mean_current_km_per_day),
        (np.array([problem.ds]), priors.sound_speed_m_s * s0 * s0),
        (problem.per_beacon(0), priors.offset_s),
        (problem.per_beacon(1), priors.drift_s_per_day),
        (problem.per_beacon(2), priors.beacon_sound_speed_m_s * s0 * s0),
    ):
        rows.add(u[idx] / sd, [(idx, np.full(len(idx), 1 / sd))], -len(idx) * float(np.log(sd)))


def _end_fix(problem: Problem, u: NDArray, priors: KalmanPriors, rows: Rows) -> int:
    """The end fix's rows (data): position and clock at the last node. Returns their count."""
    if problem.end_sd_km is None:
        return 0
    last = NODE * (problem.n_nodes - 1)
    for axis in range(2):
        _prior_row(rows, u, last + axis, problem.end_sd_km)
    _prior_row(rows, u, last + CLOCK, priors.clock_fix_s)
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
    n_end = _end_fix(problem, u, priors, fixed)
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


def _factorise(problem: Problem, normal: sparse.spmatrix) -> BorderedBanded:
    """N = J'J: banded over the nodes (5 unknowns each, coupled to the next node's: half-width
    9), bordered by the static unknowns."""
    return BorderedBanded(normal, NODE * problem.n_nodes, 2 * NODE - 1)


def solve_step(lin: Linearised, hyper: Hyper) -> tuple[NDArray[np.float64], float]:
    """The Gauss-Newton step du = -N^-1 J'r (N = J'J) and the marginal log-likelihood of the
    linearised model at its solution, with |r*|^2 = r'r + (J'r)' du (module docstring)."""
    normal, factor, step = _solved(lin, hyper)
    return step, _log_ml(lin, normal, factor, step)


def _solved(lin: Linearised, hyper: Hyper, motion_rows: Rows | None = None) -> tuple[Normal, BorderedBanded, NDArray]:
    """The normal terms under `hyper`, N's factorisation and the step -N^-1 J'r."""
    normal = lin.normal(hyper, motion_rows)
    factor = _factorise(lin.problem, normal.jtj)
    return normal, factor, -factor.solve(normal.jtr)


def _log_ml(lin: Linearised, normal: Normal, factor: BorderedBanded, step: NDArray) -> float:
    misfit = normal.rtr + float(np.einsum("i,i->", normal.jtr, step))
    return -0.5 * misfit - 0.5 * factor.log_det() + normal.log_whitening - 0.5 * lin.n_data * LOG_2PI


class _RowTerms:
    """What the evidence's derivative needs of a block of rows at the solution du* of the
    linearised model (`evidence_and_gradient`): per row its residual e* = r + J du*, and
    per Jacobian entry (row, c) the entry (N^-1 J')[c, row]."""

    def __init__(self, rows: Block, step: NDArray, factor: BorderedBanded):
        self.step_at = np.where(rows.cols >= 0, step[rows.cols], 0.0)  # -1: padding
        self.e_star = rows.residual + np.einsum("me,me->m", rows.vals, self.step_at)
        self.inverse_jt = factor.inverse_times_rows(rows.cols, rows.vals)

    def derivative(self, d_residual: NDArray, d_vals: NDArray) -> float:
        """d/dh of -|r*|^2 / 2 - log|N| / 2 given the rows' derivatives dr and dJ:
        d|r*|^2 = 2 e*'(dr + dJ du*) (du* is optimal: its own change does not count) and
        d log|N| = tr(N^-1 dN) = 2 tr(N^-1 J' dJ)."""
        de = d_residual + np.einsum("me,me->m", d_vals, self.step_at)
        return -float(np.einsum("m,m->", self.e_star, de)) - float(np.einsum("me,me->", d_vals, self.inverse_jt))


# Central differences of the motion rows in log h: the rows are closed forms of the
# hyperparameters, cheap to rebuild; a step of 1e-5 leaves errors ~1e-10 relative.
MOTION_STEP = 1e-5
MOTION_HYPER = ("velocity_sd_km_per_day", "decorrelation_days", "clock_rate_sd_s_per_day")


def evidence_and_gradient(lin: Linearised, hyper: Hyper) -> tuple[float, NDArray[np.float64]]:
    """The marginal log-likelihood of the linearised model (`solve_step`) and its gradient in
    log h, from one factorisation. With all rows whitened, r(h) and J(h),

        d log p(y | h) = -d|r*|^2 / 2 - d log|N| / 2 + d log|W|   (`_RowTerms.derivative`).

    The arrival rows scale as 1 / sigma: dr = -r and dJ = -J per unit of log sigma, and
    d log|W| = -n_arrivals. The motion rows depend on (sigma_v, T, q) through the OU and
    clock transitions: their derivatives by central differences (`MOTION_STEP`)."""
    motion = lin.motion_rows(hyper)
    normal, factor, step = _solved(lin, hyper, motion)
    log_ml = _log_ml(lin, normal, factor, step)
    grad = np.zeros(4)
    arrivals = lin.arrival_block
    sigma = hyper.toa_sigma_s
    scaled = Block(arrivals.residual / sigma, arrivals.cols, arrivals.vals / sigma)
    grad[2] = _RowTerms(scaled, step, factor).derivative(-scaled.residual, -scaled.vals)
    grad[2] -= lin.n_arrivals
    terms = _RowTerms(motion.stacked(), step, factor)
    scale = 0.5 / MOTION_STEP
    for name in MOTION_HYPER:
        value = getattr(hyper, name)
        up = lin.motion_rows(dataclasses.replace(hyper, **{name: value * np.exp(MOTION_STEP)}))
        down = lin.motion_rows(dataclasses.replace(hyper, **{name: value * np.exp(-MOTION_STEP)}))
        j = HYPER_FIELDS.index(name)
        a, b = up.stacked(), down.stacked()
        grad[j] = terms.derivative(scale * (a.residual - b.residual), scale * (a.vals - b.vals))
        grad[j] += scale * (up.log_whitening - down.log_whitening)
    return log_ml, grad


def log_hyperprior(hyper: Hyper) -> tuple[float, NDArray[np.float64]]:
    """log p(h) and its gradient in log h: independent log-normal priors (medians
    `Hyper.PRIOR_MEDIAN`, log-sds `Hyper.PRIOR_LOG_SD`). They only keep the search where the
    data do not decide: in a geometry where every source lies on one side, a common shift of
    all arrival times looks like a move towards the sources, and the clock's wander and the
    track can trade places."""
    log_sd = np.array(Hyper.PRIOR_LOG_SD)
    z = (hyper.vector() - np.log(Hyper.PRIOR_MEDIAN)) / log_sd
    return float(-0.5 * np.sum(z * z)), -z / log_sd


def fit_hyper(lin: Linearised, hyper: Hyper, lower: tuple[float, ...] = Hyper.LOWER) -> Hyper:
    """Hyperparameters maximising the marginal likelihood of the model linearised at `lin`,
    times their prior (`log_hyperprior`): quasi-Newton in log space with the gradient of
    `evidence_and_gradient`, within `lower` and `Hyper.UPPER`."""

    def cost(x: NDArray) -> tuple[float, NDArray]:
        h = Hyper.from_vector(x, lower)
        log_ml, grad = evidence_and_gradient(lin, h)
        log_prior, prior_grad = log_hyperprior(h)
        return -log_ml - log_prior, -grad - prior_grad

    bounds = list(zip(np.log(lower), np.log(Hyper.UPPER), strict=True))
    start = np.clip(hyper.vector(), *np.log([lower, Hyper.UPPER]))
    # The search stops when the log evidence (~10^3 nats) changes by less than ~1e-4 nats
    # (ftol) or its gradient is below 0.1 nats per unit of log hyperparameter (gtol: a 10%
    # change of any hyperparameter then gains at most ~0.01 nats); hyperparameters closer to
    # the optimum than that make no difference.
    options = {"ftol": 1e-7, "gtol": 0.1, "maxiter": 50}
    best = minimize(cost, start, jac=True, method="L-BFGS-B", bounds=bounds, options=options)
    return Hyper.from_vector(best.x, lower)


def position_covariances(lin: Linearised, hyper: Hyper) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(K, 2, 2) posterior position covariance at each node, [N^-1]_pp, and the part of it
    due to the clock and timing unknowns, [N^-1]_pp - [N_xx^-1]_pp (module docstring)."""
    problem = lin.problem
    normal = lin.normal(hyper).jtj
    k = np.arange(problem.n_nodes)
    total = _factorise(problem, normal).diagonal_blocks_of_inverse(NODE * k, 2)
    motion = (NODE * k[:, None] + np.arange(4)).ravel()  # positions and velocities
    given = BorderedBanded(normal[motion][:, motion], 4 * problem.n_nodes, 7).diagonal_blocks_of_inverse(4 * k, 2)
    out = total - given
    values, vectors = np.linalg.eigh(0.5 * (out + out.transpose(0, 2, 1)))  # PSD up to round-off
    return total, np.einsum("kij,kj,klj->kil", vectors, np.clip(values, 0.0, None), vectors)


def sound_speed_influence(problem: Problem, fit: KalmanFit, priors: KalmanPriors) -> tuple[NDArray[np.float64], float]:
    """How much each heard source's arrivals move the shared sound speed: per source, the
    fitted speed without them minus the fitted speed (m/s), and the speed's posterior sd
    (m/s). At the fit's linearisation, leaving out source i's rows (J_i, r_i) gives the
    solution du_-i = -(N - J_i'J_i)^-1 (J'r - J_i'r_i): one factorisation per source, no
    refit. The speed is c = 1 / (s0 + ds): dc = -c^2 d(ds)."""
    lin = linearise(problem, fit.unknowns, fit.weight, priors)
    normal, factor, step = _solved(lin, fit.hyper)
    jac, r = lin.arrival_system
    s2 = fit.hyper.toa_sigma_s**2
    e_ds = np.zeros(problem.n_unknowns)
    e_ds[problem.ds] = 1.0
    speed = fit.sound_speed_m_s
    sd = float(np.sqrt(factor.solve(e_ds)[problem.ds])) * speed**2
    ds = fit.unknowns[problem.ds] + float(step[problem.ds])
    shift = np.zeros(problem.n_heard)
    for h in range(problem.n_heard):
        own = problem.beacon == h
        without = _factorise(problem, (normal.jtj - (jac[own].T @ jac[own]) / s2).tocsr())
        ds_without = fit.unknowns[problem.ds] + float(-without.solve(normal.jtr - jac[own].T @ r[own] / s2)[problem.ds])
        shift[h] = 1.0 / (problem.slowness_s_per_m + ds_without) - 1.0 / (problem.slowness_s_per_m + ds)
    return shift, sd


@dataclass(frozen=True)
class KalmanFit:
    """The smoother's solution (module docstring)."""

    hyper: Hyper
    unknowns: NDArray[np.float64]
    lat: NDArray[np.float64]  # (K,) fitted positions
    lon: NDArray[np.float64]
    velocity_km_per_day: NDArray[np.float64]  # (K, 2)
    clock_s: NDArray[np.float64]  # (K,) clock residual
    mean_current_km_per_day: NDArray[np.float64]  # (2,)
    sound_speed_m_s: float
    beacon_sound_speed_m_s: NDArray[np.float64]  # (H,) heard beacons
    offset_s: NDArray[np.float64]  # (H,) a_i - d_i mid_i: correction to the catalogue offset
    drift_s_per_day: NDArray[np.float64]  # (H,)
    toa_residual_s: NDArray[np.float64]  # (J,)
    weight: NDArray[np.float64]  # (J,) EM weights of the arrivals (P(direct path))
    position_cov_km2: NDArray[np.float64]  # (K, 2, 2) posterior covariance of the positions
    nuisance_cov_km2: NDArray[np.float64]  # (K, 2, 2) the part of it due to clock and timing
    log_evidence: float

    def track(self, time: NDArray[np.datetime64]) -> pd.DataFrame:
        return pd.DataFrame({"time": time, "lat": self.lat, "lon": self.lon})


def fit(
    problem: Problem,
    hyper: Hyper,
    weight_of: Callable[[NDArray, float], NDArray],
    mid_days: NDArray[np.float64],
    *,
    priors: KalmanPriors = KalmanPriors(),
    iterations: int = 4,
    hyper_lower: tuple[float, ...] = Hyper.LOWER,
) -> KalmanFit:
    """Gauss-Newton with the hyperparameters refitted at each linearisation (within
    `hyper_lower` and `Hyper.UPPER`), and the arrivals' weights from their residuals by
    `weight_of(residual_s, toa_sigma_s)` (EM for multipath); `mid_days` (H,) the drift
    reference of each heard beacon."""
    u = np.zeros(problem.n_unknowns)
    weight = np.ones(len(problem.toa_s))
    for _ in range(iterations):
        lin = linearise(problem, u, weight, priors)
        hyper = fit_hyper(lin, hyper, hyper_lower)
        u = u + solve_step(lin, hyper)[0]
        weight = weight_of(linearise(problem, u, weight, priors).toa_residual_s, hyper.toa_sigma_s)
    lin = linearise(problem, u, weight, priors)
    u = u + solve_step(lin, hyper)[0]
    lin = linearise(problem, u, weight, priors)
    _, log_ml = solve_step(lin, hyper)
    lat, lon = _positions(problem, u)
    total, nuisance = position_covariances(lin, hyper)
    k = np.arange(problem.n_nodes)
    s0 = problem.slowness_s_per_m
    ds = u[problem.ds]
    a, d = u[problem.per_beacon(0)], u[problem.per_beacon(1)]
    vbar = problem.vbar
    return KalmanFit(
        hyper=hyper,
        unknowns=u,
        lat=lat,
        lon=lon,
        velocity_km_per_day=np.column_stack([u[NODE * k + VELOCITY], u[NODE * k + VELOCITY + 1]]),
        clock_s=u[NODE * k + CLOCK],
        mean_current_km_per_day=u[vbar : vbar + 2].copy(),
        sound_speed_m_s=float(1.0 / (s0 + ds)),
        beacon_sound_speed_m_s=1.0 / (s0 + ds + u[problem.per_beacon(2)]),
        offset_s=a - d * mid_days,
        drift_s_per_day=d,
        toa_residual_s=lin.toa_residual_s,
        weight=weight,
        position_cov_km2=total,
        nuisance_cov_km2=nuisance,
        log_evidence=log_ml,
    )
