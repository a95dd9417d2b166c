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

The model is in `calibrate.kalman_problem`, its rows and their normal terms in
`calibrate.kalman_rows`, its assembly at a linearisation point in `calibrate.kalman_terms`,
the solution, evidence and hyperparameter fit in `calibrate.kalman_evidence`; this module
runs the fit and re-exports what callers use.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from .kalman_evidence import (
    evidence_and_gradient,
    factorise,
    fit_hyper,
    log_hyperprior,
    position_covariances,
    solve_step,
    solved,
)
from .kalman_problem import CLOCK, NODE, VELOCITY, Hyper, KalmanPriors, Problem, node_positions
from .kalman_terms import Linearised, linearise

__all__ = [
    "Hyper",
    "KalmanFit",
    "KalmanPriors",
    "Linearised",
    "Problem",
    "evidence_and_gradient",
    "fit",
    "fit_hyper",
    "linearise",
    "log_hyperprior",
    "position_covariances",
    "solve_step",
    "sound_speed_influence",
]

DEFAULT_PRIORS = KalmanPriors()  # `fit`'s default (frozen: one shared instance)


def sound_speed_influence(problem: Problem, fit: KalmanFit, priors: KalmanPriors) -> tuple[NDArray[np.float64], float]:
    """How much each heard source's arrivals move the shared sound speed: per source, the
    fitted speed without them minus the fitted speed (m/s), and the speed's posterior sd
    (m/s). At the fit's linearisation, leaving out source i's rows (J_i, r_i) gives the
    solution du_-i = -(N - J_i'J_i)^-1 (J'r - J_i'r_i): one factorisation per source, no
    refit. The speed is c = 1 / (s0 + ds): dc = -c^2 d(ds)."""
    lin = linearise(problem, fit.unknowns, fit.weight, priors)
    normal, factor, step = solved(lin, fit.hyper)
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
        without = factorise(problem, (normal.jtj - (jac[own].T @ jac[own]) / s2).tocsr())
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
    # (H, 2) the heard sources' fitted displacement from the table (east, north km), where
    # their positions were unknowns (`Problem.source_positions`); else zeros.
    source_shift_km: NDArray[np.float64] = dataclasses.field(default_factory=lambda: np.zeros((0, 2)))

    def track(self, time: NDArray[np.datetime64]) -> pd.DataFrame:
        return pd.DataFrame({"time": time, "lat": self.lat, "lon": self.lon})


def fit(
    problem: Problem,
    hyper: Hyper,
    weight_of: Callable[[NDArray, float], NDArray],
    mid_days: NDArray[np.float64],
    *,
    priors: KalmanPriors = DEFAULT_PRIORS,
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
    lat, lon = node_positions(problem, u)
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
        source_shift_km=(
            np.column_stack([u[problem.per_beacon(3)], u[problem.per_beacon(4)]])
            if problem.source_positions
            else np.zeros((problem.n_heard, 2))
        ),
    )
