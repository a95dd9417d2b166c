"""The batch Kalman smoother's solution and evidence (`calibrate.kalman`): the Gauss-Newton
step, the marginal log-likelihood of the linearised model and its gradient in the log
hyperparameters, the hyperparameter fit, and the posterior position covariances, all from
the banded factorisation of N = J'J (`BorderedBanded`).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import NDArray
from scipy import sparse
from scipy.optimize import minimize

from .banded import BorderedBanded
from .kalman_problem import HYPER_FIELDS, LOG_2PI, NODE, Hyper, Problem
from .kalman_rows import Block, Normal, Rows
from .kalman_terms import Linearised


def factorise(problem: Problem, normal: sparse.spmatrix) -> BorderedBanded:
    """N = J'J: banded over the nodes (5 unknowns each, coupled to the next node's: half-width
    9), bordered by the static unknowns."""
    return BorderedBanded(normal, NODE * problem.n_nodes, 2 * NODE - 1)


def solve_step(lin: Linearised, hyper: Hyper) -> tuple[NDArray[np.float64], float]:
    """The Gauss-Newton step du = -N^-1 J'r (N = J'J) and the marginal log-likelihood of the
    linearised model at its solution, with |r*|^2 = r'r + (J'r)' du (module docstring)."""
    normal, factor, step = solved(lin, hyper)
    return step, _log_ml(lin, normal, factor, step)


def solved(lin: Linearised, hyper: Hyper, motion_rows: Rows | None = None) -> tuple[Normal, BorderedBanded, NDArray]:
    """The normal terms under `hyper`, N's factorisation and the step -N^-1 J'r."""
    normal = lin.normal(hyper, motion_rows)
    factor = factorise(lin.problem, normal.jtj)
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
    normal, factor, step = solved(lin, hyper, motion)
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
    total = factorise(problem, normal).diagonal_blocks_of_inverse(NODE * k, 2)
    motion = (NODE * k[:, None] + np.arange(4)).ravel()  # positions and velocities
    given = BorderedBanded(normal[motion][:, motion], 4 * problem.n_nodes, 7).diagonal_blocks_of_inverse(4 * k, 2)
    out = total - given
    values, vectors = np.linalg.eigh(0.5 * (out + out.transpose(0, 2, 1)))  # PSD up to round-off
    return total, np.einsum("kij,kj,klj->kil", vectors, np.clip(values, 0.0, None), vectors)
