"""What replaces the paper's military tank simulation: a manoeuvring random-walk target.

The paper's truth tracks came from a tank simulation (the Timeline Analysis Model) that is
not available. Ours follows the paper's description of those tracks (section 4.1) without
being the RW model itself: the target drives legs whose durations are U(5, 40) s, each
new leg turning by U(-pi/4, pi/4) from the last ("never more than pi/4 in either
direction") at a speed drawn from U(8, 17) units/s (mean 12.5 as the paper's prior, not its
normal shape); it turns at a finite rate (0.6 rad/s) and changes speed at a finite
acceleration (3 units/s^2), integrated every 0.05 s, so its corners are rounded and its
speed ramps: piecewise-straight only approximately. The plane is unbounded (the paper's
square region R is not specified).

Measurements every dT seconds from t = 0 to T, position plus noise per axis of variance
sigma^2 of one of four types (paper Fig. 7: "comparable variance"), all centred:
Gaussian N(0, sigma^2); Uniform U(-sqrt(3) sigma, sqrt(3) sigma); Gamma: exponential
(shape 1, scale sigma) minus its mean (skewed); Beta(1/2, 1/2) scaled to variance sigma^2
and centred (U-shaped: most errors near +-1.4 sigma).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

NOISE_TYPES = ("gaussian", "uniform", "gamma", "beta")
STEP_S = 0.05


@dataclass(frozen=True)
class TargetConfig:
    duration_s: tuple[float, float] = (5.0, 40.0)
    max_turn_rad: float = math.pi / 4
    speed: tuple[float, float] = (8.0, 17.0)
    turn_rate_rad_s: float = 0.6
    acceleration: float = 3.0


@dataclass(frozen=True)
class Scenario:
    """One run's settings (paper section 6 defaults: T 200 s, sigma^2 5, dT 5 s, Gaussian)."""

    total_s: float = 200.0
    sigma2: float = 5.0
    interval_s: float = 5.0
    noise: str = "gaussian"


@dataclass(frozen=True)
class Run:
    """A simulated target, its measurements and the times the error is scored at."""

    scenario: Scenario
    truth_t: NDArray[np.float64]
    truth_xy: NDArray[np.float64]
    meas_t: NDArray[np.float64]
    meas_xy: NDArray[np.float64]
    eval_t: NDArray[np.float64]  # t = 1..T (paper's SS sums over t = 1..T)

    def truth_at(self, times: NDArray) -> NDArray[np.float64]:
        return np.column_stack([np.interp(times, self.truth_t, self.truth_xy[:, k]) for k in range(2)])


def simulate_target(
    total_s: float, rng: np.random.Generator, cfg: TargetConfig = TargetConfig()
) -> tuple[NDArray, NDArray]:
    """Times (every STEP_S) and positions of one target track (module docstring)."""
    n = math.ceil(total_s / STEP_S) + 1
    xy = np.zeros((n, 2))
    heading = rng.uniform(-math.pi, math.pi)
    speed = rng.uniform(*cfg.speed)
    goal_heading, goal_speed = heading, speed
    leg_end = rng.uniform(*cfg.duration_s)
    x = y = 0.0
    max_turn, max_accel = cfg.turn_rate_rad_s * STEP_S, cfg.acceleration * STEP_S
    for k in range(1, n):
        t = k * STEP_S
        if t >= leg_end:
            goal_heading += rng.uniform(-cfg.max_turn_rad, cfg.max_turn_rad)
            goal_speed = rng.uniform(*cfg.speed)
            leg_end += rng.uniform(*cfg.duration_s)
        heading += min(max(goal_heading - heading, -max_turn), max_turn)
        speed += min(max(goal_speed - speed, -max_accel), max_accel)
        x += speed * math.cos(heading) * STEP_S
        y += speed * math.sin(heading) * STEP_S
        xy[k] = (x, y)
    return np.arange(n) * STEP_S, xy


def measurement_noise(kind: str, sigma2: float, size: int, rng: np.random.Generator) -> NDArray[np.float64]:
    """(size, 2) centred noise of variance sigma2 per axis (module docstring)."""
    sd = math.sqrt(sigma2)
    if kind == "gaussian":
        return rng.normal(0.0, sd, (size, 2))
    if kind == "uniform":
        return rng.uniform(-math.sqrt(3) * sd, math.sqrt(3) * sd, (size, 2))
    if kind == "gamma":
        return rng.gamma(1.0, sd, (size, 2)) - sd
    if kind == "beta":
        return (rng.beta(0.5, 0.5, (size, 2)) - 0.5) * sd / math.sqrt(0.125)
    raise ValueError(f"unknown noise type {kind!r}; expected one of {', '.join(NOISE_TYPES)}")


def make_run(scenario: Scenario, rng: np.random.Generator, cfg: TargetConfig = TargetConfig()) -> Run:
    """Simulate the target, then measure it (module docstring)."""
    truth_t, truth_xy = simulate_target(scenario.total_s, rng, cfg)
    meas_t = np.arange(0.0, scenario.total_s + 1e-9, scenario.interval_s)
    run = Run(scenario, truth_t, truth_xy, meas_t, np.zeros((len(meas_t), 2)), np.arange(1.0, scenario.total_s + 1e-9))
    noise = measurement_noise(scenario.noise, scenario.sigma2, len(meas_t), rng)
    return Run(scenario, truth_t, truth_xy, meas_t, run.truth_at(meas_t) + noise, run.eval_t)
