"""The ABC paper's simulation setting (section 5) on `rafostrack.sensors`, the choices it leaves
open, its Table 1, and the seeded runner shared by the experiments.

One task runs one algorithm on R scenarios of one cell (sensors, targets): the cell's
scenarios are drawn from the cell's own seed, so every algorithm of a cell sees the same
scenarios (paired comparisons), whichever worker runs it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from rafostrack.sensors import NAMES, Settings, initial_estimates, rmse, sensor_grid, simulate_truth, track
from rafostrack.sensors.sensors import START_RADIUS, STEPS, VELOCITY_VAR
from rafostrack.sensors.tracking import expected_distance, paper_tolerance

P_CORRECT = 0.95  # pe: the paper does not give it
SPEED = 2.0  # units/s towards the centre: the paper does not give it
HALF_WIDTH = 50.0  # sensors on a regular grid over [-50, 50]^2
INIT_POSITION_SD = 1.0
INIT_VELOCITY_SD = 0.3
TIMES = (10, 20, 30)
ALGORITHM_ORDER = ("rej", "rw", "pt", "mcmc")
PAPER_ALGORITHMS = ("rej", "rw", "pt")

# Table 1 of the paper: RMSE (its bracketed "standard error") at t for Nt targets and Ns sensors.
PAPER_TABLE1: dict[tuple[int, int], dict[int, dict[str, tuple[float, float]]]] = {
    (2, 10): {16: {"rej": (9.70, 3.40), "rw": (8.80, 3.32), "pt": (5.34, 1.18)},
              64: {"rej": (9.96, 3.57), "rw": (9.27, 2.56), "pt": (3.39, 1.44)}},
    (2, 20): {16: {"rej": (20.37, 6.20), "rw": (18.96, 6.17), "pt": (8.29, 4.81)},
              64: {"rej": (21.64, 6.71), "rw": (17.24, 6.12), "pt": (6.03, 5.59)}},
    (2, 30): {16: {"rej": (34.21, 9.83), "rw": (21.98, 6.89), "pt": (12.75, 6.06)},
              64: {"rej": (37.32, 10.37), "rw": (21.73, 6.89), "pt": (9.39, 5.64)}},
    (3, 10): {16: {"rej": (11.88, 6.02), "rw": (9.30, 3.78), "pt": (6.84, 1.56)},
              64: {"rej": (12.91, 4.26), "rw": (9.87, 3.39), "pt": (3.15, 1.42)}},
    (3, 20): {16: {"rej": (20.53, 7.07), "rw": (19.96, 6.88), "pt": (12.50, 4.72)},
              64: {"rej": (20.15, 5.21), "rw": (19.11, 6.56), "pt": (5.34, 4.28)}},
    (3, 30): {16: {"rej": (36.91, 11.05), "rw": (23.30, 6.27), "pt": (15.88, 6.40)},
              64: {"rej": (36.93, 11.63), "rw": (23.06, 6.86), "pt": (13.25, 5.45)}},
    (4, 10): {16: {"rej": (11.62, 3.18), "rw": (9.64, 3.20), "pt": (6.02, 1.48)},
              64: {"rej": (11.25, 3.82), "rw": (10.23, 3.26), "pt": (4.80, 2.23)}},
    (4, 20): {16: {"rej": (25.35, 8.14), "rw": (20.90, 7.79), "pt": (12.67, 3.00)},
              64: {"rej": (24.58, 8.41), "rw": (20.39, 8.00), "pt": (12.57, 4.43)}},
    (4, 30): {16: {"rej": (43.85, 14.84), "rw": (23.31, 7.07), "pt": (16.80, 5.56)},
              64: {"rej": (43.18, 14.22), "rw": (24.12, 6.96), "pt": (16.24, 6.40)}},
}  # fmt: skip


def describe() -> str:
    """The setting, with every choice the paper leaves open, for REPORT.md."""
    tol = ", ".join(
        f"Ns = {ns}, Nt = {nt}: {expected_distance(ns, nt, P_CORRECT):.1f} (paper's rule "
        f"{paper_tolerance(ns, nt, P_CORRECT):.2f})"
        for ns, nt in ((16, 2), (64, 2), (64, 4))
    )
    return (
        f"Targets follow eq. 1 with sigma^2 = {VELOCITY_VAR} (one step per second, {STEPS} s), starting at random "
        f"angles on the circle of radius {START_RADIUS:g} heading for the centre at {SPEED:g} units/s (speed not "
        "given in the paper); the velocity is indexed by the step it drives (x_t = x_{t-1} + v_t), so the sensors "
        f"at t see the direction of motion at x_t. Sensors sit on a regular grid over [-{HALF_WIDTH:g}, "
        f"{HALF_WIDTH:g}]^2 (layout not given); each reports each target's closer/away bit correctly with "
        f"probability pe = {P_CORRECT} (not given), and only the count of its bits (eq. 2). Every algorithm "
        "starts from the truth with N(0, 1) position and N(0, 0.3^2) velocity errors per coordinate and, at each "
        "step, draws from pi_0(x^_{t-1}, v^_{t-1}): v_t ~ N(v^_{t-1}, sigma^2 I), x_t = x^_{t-1} + v_t; the "
        "estimate is the mean of the retained states. Tolerance: the paper's rule epsilon = Ns (pe Nt)^2 (pe there "
        "the error probability) accepts essentially nothing when the simulations include the sensors' errors, so "
        "epsilon is the mean distance of the true state, 2 Ns Nt pe (1 - pe) (" + tol + "). When no draw of a step "
        "is within epsilon, the draws at the smallest distance are used (nearest-neighbour fallback, counted). "
        "ABC-RW's f is Gaussian in the change of bearing and of step length with the scales eq. 1 implies "
        "(sigma / |v|, sigma); ABC-PT runs 5 chains with epsilon_c = epsilon * 2^((c-1)/2) and 5 swap proposals "
        "per iteration. The exact-likelihood MCMC is a random walk with sd 0.3 per coordinate (about 22% accepted "
        "for one target and 64 sensors), 10% burn-in, started at the prior mean; for Nt > 1 it uses the exact "
        "Poisson-binomial likelihood (the paper's eq. 7, which it calls intractable) and is our reference, not the "
        "paper's."
    )


@dataclass(frozen=True)
class CellTask:
    """One algorithm on the R scenarios of one cell."""

    n_sensors: int
    n_targets: int
    algorithm: str
    scenarios: int
    particles: int
    seed: int


def run_task(task: CellTask) -> dict[str, Any]:
    """RMSE (R, T + 1) and diagnostics of one algorithm on one cell's scenarios."""
    sensors = sensor_grid(task.n_sensors, HALF_WIDTH)
    scenario_rng = np.random.default_rng([task.seed, task.n_sensors, task.n_targets])
    truth = simulate_truth(task.scenarios, task.n_targets, sensors, P_CORRECT, scenario_rng, speed=SPEED)
    x0, v0 = initial_estimates(truth, scenario_rng, INIT_POSITION_SD, INIT_VELOCITY_SD)
    settings = Settings(task.algorithm, particles=task.particles, p_correct=P_CORRECT)
    algo_rng = np.random.default_rng([task.seed, task.n_sensors, task.n_targets, ALGORITHM_ORDER.index(task.algorithm)])
    result = track(truth, sensors, x0, v0, settings, algo_rng)
    return {
        "n_sensors": task.n_sensors,
        "n_targets": task.n_targets,
        "algorithm": task.algorithm,
        "name": NAMES[task.algorithm],
        "rmse": rmse(result.x_hat, truth.x),
        "acceptance": float(result.acceptance.mean()),
        "fallback": float(result.fallback.mean()),
        "swap_acceptance": None if result.swap_acceptance is None else float(result.swap_acceptance.mean()),
        "seconds_per_scenario": result.seconds / task.scenarios,
        "simulations_per_step": settings.simulations_per_step(),
        "tolerance": result.tolerance,
    }
