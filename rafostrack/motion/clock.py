"""The float clock as part of the state: a random walk about the table's clock.

floats.csv gives the float clock's offsets at launch and at the end, and the arrivals are
predicted with the clock interpolated between them (`FloatInfo.clock_offset_s`). A wrong
or missing end offset then shifts every source's predicted arrival by the same error, which
grows through the record: a filter that trusts it moves the float to explain a shift that
is the clock's. `ClockWalk` adds each particle's correction c to that clock (seconds,
`Particles.clock_s`; the arrivals' predictions add it, `likelihoods.arrivals`), drawn
about the launch offset and drifting as a random walk,

    c_0 ~ N(0, s0^2),    c' = c + q sqrt(dt) z,   z ~ N(0, 1),

independent of the drift. A common shift of every source's arrivals is then the clock's,
not a move, wherever three or more sources around the float are heard; where fewer are,
the walk's q bounds how far the clock can stand in for a move. Real clocks drift linearly
by up to about 0.3 s a day; a walk of q = 0.5 s per sqrt(day) follows such a drift within
about a second at a window a day.

The wrapper keeps the drift model's own layout for what moves the position (`transition`,
`origin_states`, `plane_states`: a data-driven proposal redraws positions and velocities
and carries the clock of the motion's draw, `log_carried_transition`), and adds the clock
to the state the smoother weighs (`dim`, `components`: each kernel with the walk's block).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..config import MotionConfig
from ..domain import Particles
from .base import LinearGaussian, MotionModel

_LOG_2PI = float(np.log(2.0 * np.pi))
_MIN_SD_S = 1e-3  # the walk's sd floor for a step of dt = 0 (copies of the same particles)


@dataclass(frozen=True)
class ClockWalk(MotionModel):
    """`base`'s drift with the float clock's correction as a random walk (module docstring)."""

    base: MotionModel
    walk_s_per_sqrt_day: float  # q
    start_sd_s: float  # s0

    @property
    def name(self) -> str:  # type: ignore[override]
        return self.base.name

    @property
    def has_velocity(self) -> bool:  # type: ignore[override]
        return self.base.has_velocity

    @property
    def dim(self) -> int:
        """The drift's state and the clock."""
        return self.base.dim + 1

    @classmethod
    def from_config(cls, cfg: MotionConfig) -> MotionModel:
        raise TypeError("ClockWalk wraps a configured model: build it with ClockWalk(base, q, s0)")

    def reversed(self) -> MotionModel:
        """The walk is the same backwards in time."""
        return ClockWalk(self.base.reversed(), self.walk_s_per_sqrt_day, self.start_sd_s)

    def transition(self, dt_days: float) -> LinearGaussian:
        """The drift's transition, without the clock (what a proposal redraws)."""
        return self.base.transition(dt_days)

    def origin_states(self, particles: Particles) -> NDArray[np.float64]:
        return self.base.origin_states(particles)

    def plane_states(self, now: Particles, nxt: Particles) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        return self.base.plane_states(now, nxt)

    def components(self, dt_days: float) -> list[tuple[float, LinearGaussian]]:
        """The drift's kernels, each with the clock's block appended (the state the smoother
        weighs: the drift's, then the clock)."""
        sd = max(self.walk_s_per_sqrt_day * np.sqrt(max(dt_days, 0.0)), _MIN_SD_S)
        return [(w, _with_clock(k, sd)) for w, k in self.base.components(dt_days)]

    def log_carried_transition(self, now: Particles, nxt: Particles, dt_days: float) -> NDArray[np.float64]:
        """log N(c'; c, q^2 dt) of each particle's clock."""
        clock_now, clock_next = _clock(now), _clock(nxt)
        sd = max(self.walk_s_per_sqrt_day * np.sqrt(max(dt_days, 0.0)), _MIN_SD_S)
        z = (clock_next - clock_now) / sd
        return -0.5 * z * z - np.log(sd) - 0.5 * _LOG_2PI

    def log_transition(self, now: Particles, nxt: Particles, dt_days: float) -> NDArray[np.float64]:
        """The drift's density times the clock's."""
        return self.base.log_transition(now, nxt, dt_days) + self.log_carried_transition(now, nxt, dt_days)

    def stationary_velocity(self) -> tuple[NDArray[np.float64], float]:
        return self.base.stationary_velocity()

    def log_invariant_density(self, particles: Particles) -> NDArray[np.float64]:
        """The drift's (flat in the clock, as in position)."""
        return self.base.log_invariant_density(particles)

    def initial(self, lat: float, lon: float, sd_km: float, n: int, rng: np.random.Generator) -> Particles:
        """The drift's particles about the fix, then their clocks ~ N(0, s0^2)."""
        particles = self.base.initial(lat, lon, sd_km, n, rng)
        return particles.with_clock(rng.normal(0.0, self.start_sd_s, n))

    def step(self, particles: Particles, dt_days: float, noise: NDArray[np.float64]) -> Particles:
        """The drift's step with noise rows (dim - 1, P), then the clock's with the last row."""
        moved = self.base.step(particles, dt_days, noise[:-1])
        sd = self.walk_s_per_sqrt_day * np.sqrt(max(dt_days, 0.0))
        return moved.with_clock(_clock(particles) + sd * noise[-1])

    def propagate(self, particles: Particles, dt_days: float, rng: np.random.Generator) -> Particles:
        """The drift's draw (its own, e.g. with jumps), then the clock's step."""
        moved = self.base.propagate(particles, dt_days, rng)
        sd = self.walk_s_per_sqrt_day * np.sqrt(max(dt_days, 0.0))
        return moved.with_clock(_clock(particles) + sd * rng.standard_normal(len(particles)))


def _clock(particles: Particles) -> NDArray[np.float64]:
    if particles.clock_s is None:
        raise ValueError("ClockWalk needs particles with a clock (drawn by its `initial`)")
    return particles.clock_s


def _with_clock(kernel: LinearGaussian, sd_s: float) -> LinearGaussian:
    """`kernel` on the state with the clock appended: A and L block-diagonal with (1, sd_s)."""
    d = kernel.dim
    a, lower = np.eye(d + 1), np.zeros((d + 1, d + 1))
    a[:d, :d], lower[:d, :d] = kernel.A, kernel.L
    lower[d, d] = sd_s
    return LinearGaussian(a, np.append(kernel.b, 0.0), lower)
