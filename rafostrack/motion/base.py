"""The motion-model interface: how a float drifts between two times.

A motion model is a Markov transition density f(x' | x, dt) on the float's state: its
position and, for velocity-persistent models, its east/north velocity (km/day). Every
model here is linear-Gaussian in the local east/north tangent plane of the particle it
moves (positions in km relative to the particle, velocities in km/day):

    x' = A(dt) x + b(dt) + e,   e ~ N(0, Q(dt)),

with x = (east, north) or (east, north, v_east, v_north). One definition serves the
simulator (`step` with given noise), the filter (`propagate`: exact sampling over any dt,
so a multi-day gap is one exact transition, not a chain of daily steps) and the smoother
(`transition` gives A, b, Q for the pairwise densities of FFBSm).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from ..config import MotionConfig
from ..domain import Particles
from ..geodesy import displace

# Positions are kept off the poles, where east/north displacements are undefined.
_MAX_LAT = 89.999


@dataclass(frozen=True)
class LinearGaussian:
    """x' = A x + b + L z, z ~ N(0, I): a transition in the tangent-plane state (km; km/day),
    with noise covariance Q = L L^T kept in square-root form."""

    A: NDArray[np.float64]  # (d, d)
    b: NDArray[np.float64]  # (d,)
    L: NDArray[np.float64]  # (d, d), a square root of Q; singular where dt = 0

    @property
    def dim(self) -> int:
        return len(self.b)

    @property
    def Q(self) -> NDArray[np.float64]:
        return self.L @ self.L.T

    def whitening(self, min_sd_km: float) -> NDArray[np.float64]:
        """W with W (x' - A x - b) ~ N(0, I), for Q floored at `min_sd_km`^2 per axis (a
        transition over dt = 0, between copies of the same particles, has Q = 0)."""
        diag = np.diag(self.L)
        if np.allclose(self.L, np.diag(diag)):
            return np.diag(1.0 / np.maximum(diag, min_sd_km))
        q = self.Q + min_sd_km**2 * np.eye(self.dim) * (np.linalg.eigvalsh(self.Q).min() < min_sd_km**2)
        return np.linalg.inv(np.linalg.cholesky(q))


class MotionModel(ABC):
    """A drift model: sampling, exact transitions over any interval, and its state layout."""

    name: ClassVar[str]
    has_velocity: ClassVar[bool]

    @property
    def dim(self) -> int:
        """Tangent-plane state dimension: 2 (position) or 4 (position and velocity)."""
        return 4 if self.has_velocity else 2

    @classmethod
    @abstractmethod
    def from_config(cls, cfg: MotionConfig) -> MotionModel:
        """The model with the `[motion]` settings it uses."""

    @abstractmethod
    def transition(self, dt_days: float) -> LinearGaussian:
        """A(dt), b(dt) and the noise factor L(dt) of the exact transition over `dt_days` (>= 0)."""

    def stationary_velocity(self) -> tuple[NDArray[np.float64], float]:
        """Mean (east, north) and per-axis sd (km/day) of the velocity a freshly launched
        float is given; only for models with velocity."""
        raise NotImplementedError(f"motion model {self.name!r} has no velocity")

    def initial(self, lat: float, lon: float, sd_km: float, n: int, rng: np.random.Generator) -> Particles:
        """n particles about a position fix with sd `sd_km` per axis; a velocity, where the
        model has one, drawn from its stationary law (position draws first, then velocity)."""
        east, north = rng.normal(0.0, sd_km, size=(2, n))
        new_lat, new_lon = displace(np.full(n, lat), np.full(n, lon), east, north)
        velocity = None
        if self.has_velocity:
            mean, sd = self.stationary_velocity()
            velocity = np.ascontiguousarray((mean[:, None] + sd * rng.standard_normal((2, n))).T)
        return Particles(np.clip(new_lat, -_MAX_LAT, _MAX_LAT), new_lon, velocity)

    def step(self, particles: Particles, dt_days: float, noise: NDArray[np.float64]) -> Particles:
        """The transition with given standard-normal `noise` (shape (dim, P)): deterministic,
        so a simulator can reuse the same noise (e.g. to bridge a track to an end fix)."""
        tr = self.transition(max(dt_days, 0.0))
        n = len(particles)
        state = np.zeros((tr.dim, n))
        if self.has_velocity:
            if particles.velocity_km_per_day is None:
                raise ValueError(f"motion model {self.name!r} needs particles with a velocity")
            state[2:] = particles.velocity_km_per_day.T
        # No BLAS: einsum's own loops give the same bits whatever the thread count.
        moved = np.einsum("ij,jp->ip", tr.A, state) + tr.b[:, None] + np.einsum("ij,jp->ip", tr.L, noise)
        lat, lon = displace(particles.lat, particles.lon, moved[0], moved[1])
        velocity = np.ascontiguousarray(moved[2:].T) if self.has_velocity else None
        return Particles(np.clip(lat, -_MAX_LAT, _MAX_LAT), lon, velocity)

    def propagate(self, particles: Particles, dt_days: float, rng: np.random.Generator) -> Particles:
        """Sample x' ~ f(. | x, dt) for every particle (exact over any `dt_days`)."""
        return self.step(particles, dt_days, rng.standard_normal((self.dim, len(particles))))
