"""The methods compared on one run: the paper's RW sampler, ours, and the Kalman baseline.

- `rw_paper`: the paper's system: theta_0 from the data (k in {5, ..., 50}), fixed K, the
  paper's moves and proposals, its score as the likelihood the way its MCMC toolbox uses
  a score, exp(-S / (2 sigma2)) with the toolbox's default sigma2 = 1, the start fixed at
  the first measurement, a quarter burn-in, the estimate the trajectory of the chain's
  mean parameters;
- `rw_paper_var`: the same with sigma2 = the measurement variance (floored at 1), the
  other reading of "the covariance matrix associated with the measurements" (section 5);
- `rw_ours`: the same prior, theta_0 over every k in 1..50 (the paper's multiples of 5 can
  only misalign legs with the measurements when T / dT is not one), a Gaussian likelihood (sd given, floored at
  1; Student-t with 4 dof and the same variance as `rw_student`), our knot, shift and
  start moves beside the paper's, reversible jump over K, and the pointwise posterior
  mean as the estimate;
- `kf` / `ks`: the constant-velocity Kalman filter (the paper's baseline) and its RTS
  smoother, both with EM-learnt noise levels.

Errors: the paper's SS = sum_{t=1..T} |z_t - x_t| and SS / T.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from rafostrack.legs.kalman import cv_estimates
from rafostrack.legs.model import LegPrior
from rafostrack.legs.sampler import SamplerConfig, run_chain
from rafostrack.legs.scores import GaussianLikelihood, Measurements, PaperScoreLikelihood, StudentLikelihood
from rafostrack.legs.summaries import mean_track, paper_estimate
from rafostrack.legs.theta0 import data_driven_start
from rafostrack.legs.trajectory import positions

from .target import Run

PRIOR = LegPrior()  # the paper's
OUR_LEG_COUNTS = tuple(range(1, 51))  # every k up to 50, not only multiples of 5
OUR_MOVES = {"leg": 1.0, "knot": 2.0, "shift": 1.0, "start": 0.5, "jump": 1.0}
MIN_SIGMA2 = 1.0
TOOLBOX_SIGMA2 = 1.0  # the MCMC toolbox's default `sigma2`
STUDENT_DOF = 4.0
METHODS = ("rw_paper", "rw_ours", "kf", "ks")
ALL_METHODS = ("rw_paper", "rw_paper_var", "rw_ours", "rw_student", "kf", "ks")  # fixed order: seed streams
LABELS = {
    "rw_paper": "RW, paper (score, toolbox sigma2 = 1)",
    "rw_paper_var": "RW, paper (score, sigma2 = noise variance)",
    "rw_ours": "RW, ours (Gaussian, reversible jump)",
    "rw_student": "RW, ours (Student-t 4 dof, reversible jump)",
    "kf": "Kalman filter (EM)",
    "ks": "Kalman smoother (EM)",
}


def ss_error(estimate_xy: np.ndarray, run: Run) -> float:
    """The paper's SS: sum over t = 1..T of the Euclidean error."""
    r = estimate_xy - run.truth_at(run.eval_t)
    return float(np.hypot(r[:, 0], r[:, 1]).sum())


def rw_paper(run: Run, iterations: int, rng: np.random.Generator, given_variance: bool = False) -> np.ndarray:
    data = Measurements(run.meas_t, run.meas_xy)
    start = data_driven_start(data, PRIOR)
    sigma2 = max(run.scenario.sigma2, MIN_SIGMA2) if given_variance else TOOLBOX_SIGMA2
    chain = run_chain(
        PaperScoreLikelihood(data, sigma2), PRIOR, start, SamplerConfig(iterations=iterations), rng, free_start=False
    )
    return positions(paper_estimate(chain), run.eval_t)


def rw_ours(run: Run, iterations: int, rng: np.random.Generator, student: bool = False) -> np.ndarray:
    data = Measurements(run.meas_t, run.meas_xy)
    start = data_driven_start(data, PRIOR, OUR_LEG_COUNTS)
    sd = math.sqrt(max(run.scenario.sigma2, MIN_SIGMA2))
    if student:
        likelihood: Any = StudentLikelihood(data, sd * math.sqrt((STUDENT_DOF - 2) / STUDENT_DOF), STUDENT_DOF)
    else:
        likelihood = GaussianLikelihood(data, sd)
    config = SamplerConfig(iterations=iterations, moves=OUR_MOVES, knot_step=sd, shift_step=2.0, start_step=sd / 4)
    chain = run_chain(likelihood, PRIOR, start, config, rng, free_start=True)
    return mean_track(chain, run.eval_t)


def run_methods(run: Run, iterations: int, seed: list[int], methods: tuple[str, ...] = METHODS) -> list[dict[str, Any]]:
    """SS, SS / T and seconds of every method on one run (each sampler its own seeded stream)."""
    rows = []
    kalman: tuple[np.ndarray, np.ndarray] | None = None
    for method in methods:
        k = ALL_METHODS.index(method)
        started = time.perf_counter()
        if method in ("rw_paper", "rw_paper_var"):
            z = rw_paper(run, iterations, np.random.default_rng([*seed, k]), given_variance=method == "rw_paper_var")
        elif method in ("rw_ours", "rw_student"):
            z = rw_ours(run, iterations, np.random.default_rng([*seed, k]), student=method == "rw_student")
        elif method in ("kf", "ks"):
            if kalman is None:
                filt, smooth, _ = cv_estimates(run.meas_t, run.meas_xy, run.eval_t)
                kalman = (filt, smooth)
            z = kalman[0] if method == "kf" else kalman[1]
        else:
            raise ValueError(f"unknown method {method!r}")
        ss = ss_error(z, run)
        rows.append(
            {
                "method": method,
                "ss": ss,
                "ss_per_time": ss / run.scenario.total_s,
                "seconds": time.perf_counter() - started,
            }
        )
    return rows
