"""Velocity-persistent drift: an integrated Ornstein-Uhlenbeck velocity around a mean current.

The usual description of float and drifter motion (e.g. Griffa 1996, "Applications of
stochastic particle models to oceanographic problems"): per axis, with velocity
v = vbar + u,

    du = -u / T dt + sigma sqrt(2 / T) dW,      dx = v dt,

so u has stationary sd sigma (`velocity_sd_km_per_day`) and decorrelation time T
(`decorrelation_days`). Over an interval D, with a = exp(-D / T), the exact transition is
linear-Gaussian (per axis, independent axes):

    v' = a v + (1 - a) vbar + e_v,
    x' = x + T (1 - a) v + (D - T (1 - a)) vbar + e_x,
    Var e_v = sigma^2 (1 - a^2),
    Var e_x = sigma^2 T^2 (2 D / T - 3 + 4 a - a^2),
    Cov(e_x, e_v) = sigma^2 T (1 - a)^2.

For D << T the float moves ballistically (x' ~ x + v D); for D >> T it diffuses with
D_eff^2 = 2 sigma^2 T per axis per day: the spread after a k-day gap grows as the physics
says, and a float carried by a current keeps being carried while it is not heard.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..config import MotionConfig
from .base import LinearGaussian, MotionModel


def ou_axis_moments(dt_days: ArrayLike, sd: float, timescale: float) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """(a, Var e_x, Cov(e_x, e_v), Var e_v) of one axis over `dt_days` (module docstring),
    elementwise for an array of intervals.

    Var e_x is computed as sigma^2 T^2 (2 d - 3 + 4 a - a^2) with d = D / T, written as
    2 sigma^2 T^2 (d - 2 (1 - a) + (1 - a^2) / 2) using expm1 so that it stays accurate
    (non-negative, ~ 2 sigma^2 D^3 / (3 T)) for D << T.
    """
    d = np.maximum(np.asarray(dt_days, dtype=float), 0.0) / timescale
    one_minus_a = -np.expm1(-d)
    a = 1.0 - one_minus_a
    # 2 d - 3 + 4 a - a^2 = 2 (d - one_minus_a) - one_minus_a^2 ; d - (1 - e^-d) by series when small.
    d_minus = np.where(d < 1e-3, d * d / 2.0 - d**3 / 6.0 + d**4 / 24.0, d - one_minus_a)
    var_x = sd * sd * timescale * timescale * np.maximum(2.0 * d_minus - one_minus_a * one_minus_a, 0.0)
    cov_xv = sd * sd * timescale * one_minus_a * one_minus_a
    var_v = sd * sd * one_minus_a * (1.0 + a)
    return a, var_x, cov_xv, var_v


@dataclass(frozen=True)
class IntegratedOU(MotionModel):
    """Position and velocity; the velocity relaxes to the mean current with timescale T."""

    name = "ou"
    has_velocity = True

    velocity_sd_km_per_day: float
    decorrelation_days: float
    mean_current_km_per_day: tuple[float, float] = field(default=(0.0, 0.0))

    @classmethod
    def from_config(cls, cfg: MotionConfig) -> IntegratedOU:
        return cls(
            cfg.velocity_sd_km_per_day,
            cfg.decorrelation_days,
            (cfg.mean_current_east_km_per_day, cfg.mean_current_north_km_per_day),
        )

    def stationary_velocity(self) -> tuple[NDArray[np.float64], float]:
        return np.asarray(self.mean_current_km_per_day, dtype=float), self.velocity_sd_km_per_day

    def reversed(self) -> MotionModel:
        east, north = self.mean_current_km_per_day
        return dataclasses.replace(self, mean_current_km_per_day=(-east, -north))

    def transition(self, dt_days: float) -> LinearGaussian:
        """State (east, north, v_east, v_north); the Cholesky factor per axis in closed form."""
        east, north = self.mean_current_km_per_day
        return _transition(self.velocity_sd_km_per_day, self.decorrelation_days, east, north, max(dt_days, 0.0))


@functools.lru_cache(maxsize=256)
def _transition(sd: float, t: float, east: float, north: float, dt: float) -> LinearGaussian:
    """`IntegratedOU.transition`, kept for the intervals met again (a record's windows are
    mostly a day apart: the filter, the backward filter and the smoothers ask for the same
    few intervals thousands of times); its arrays are read-only."""
    a, var_x, cov_xv, var_v = (float(x) for x in ou_axis_moments(dt, sd, t))
    vbar = np.array([east, north], dtype=float)
    i2 = np.eye(2)
    A = np.block([[i2, t * (1.0 - a) * i2], [np.zeros((2, 2)), a * i2]])
    b = np.concatenate([(dt - t * (1.0 - a)) * vbar, (1.0 - a) * vbar])
    # Per axis, the Cholesky factor of [[var_v, cov], [cov, var_x]] ordered (v, x), so that
    # the velocity noise is one standard normal and x takes the rest: exact at dt -> 0.
    l_vv = math.sqrt(var_v)
    l_xv = cov_xv / l_vv if l_vv > 0 else 0.0
    l_xx = math.sqrt(max(var_x - l_xv * l_xv, 0.0))
    L = np.zeros((4, 4))
    for axis in range(2):
        x, v = axis, axis + 2
        L[x, x], L[x, v], L[v, v] = l_xx, l_xv, l_vv
    for array in (A, b, L):
        array.setflags(write=False)
    return LinearGaussian(A=A, b=b, L=L)
