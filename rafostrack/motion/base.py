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

import functools
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from ..config import MotionConfig
from ..domain import Particles
from ..model.geodesy import displace, local_offsets_km

# Positions are kept off the poles, where east/north displacements are undefined.
_MAX_LAT = 89.999


@dataclass(frozen=True)
class LinearGaussian:
    """x' = A x + b + L z, z ~ N(0, I): a transition in the tangent-plane state (km; km/day),
    with noise covariance Q = L L^T kept in square-root form."""

    A: NDArray[np.float64]  # (d, d)
    b: NDArray[np.float64]  # (d,)
    L: NDArray[np.float64]  # (d, d), a square root of Q; singular where dt = 0
    # `whitened`'s results by floor: a transition met again (the filters and smoothers ask
    # for the same few intervals thousands of times) is whitened once.
    _whitened: dict[float, tuple[NDArray[np.float64], float]] = field(
        default_factory=dict, init=False, repr=False, compare=False
    )

    @property
    def dim(self) -> int:
        return len(self.b)

    @property
    def Q(self) -> NDArray[np.float64]:
        return self.L @ self.L.T

    def log_density(self, now: NDArray[np.float64], nxt: NDArray[np.float64], min_sd_km: float = 1e-3) -> NDArray:
        """log N(nxt; A now + b, Q) for states (P, d), elementwise (Q floored as in `whitening`)."""
        white, log_det = self.whitened(min_sd_km)
        z = np.einsum("kl,pl->pk", white, nxt - np.einsum("kl,pl->pk", self.A, now) - self.b)
        return -0.5 * np.einsum("pk,pk->p", z, z) + log_det - 0.5 * self.dim * np.log(2.0 * np.pi)

    def whitened(self, min_sd_km: float) -> tuple[NDArray[np.float64], float]:
        """The `whitening` W (read-only) and log |W|."""
        if min_sd_km not in self._whitened:
            white = self.whitening(min_sd_km)
            white.setflags(write=False)
            self._whitened[min_sd_km] = white, float(np.linalg.slogdet(white)[1])
        return self._whitened[min_sd_km]

    def whitening(self, min_sd_km: float) -> NDArray[np.float64]:
        """W with W (x' - A x - b) ~ N(0, I), for Q floored at `min_sd_km`^2 per axis (a
        transition over dt = 0, between copies of the same particles, has Q = 0)."""
        diag = np.diag(self.L)
        if np.allclose(self.L, np.diag(diag)):
            return np.diag(1.0 / np.maximum(diag, min_sd_km))
        q = self.Q + min_sd_km**2 * np.eye(self.dim) * (np.linalg.eigvalsh(self.Q).min() < min_sd_km**2)
        return np.linalg.inv(np.linalg.cholesky(q))


def from_plane_states(origins: Particles, states: NDArray[np.float64], has_velocity: bool) -> Particles:
    """The particles at tangent-plane `states` (P, d) of `origins`, particle by particle (east
    and north km from each origin, then the velocity if any): the inverse of
    `MotionModel.plane_states`, positions kept off the poles."""
    lat, lon = displace(origins.lat, origins.lon, states[:, 0], states[:, 1])
    velocity = np.ascontiguousarray(states[:, 2:]) if has_velocity else None
    return Particles(np.clip(lat, -_MAX_LAT, _MAX_LAT), lon, velocity)


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
    def reversed(self) -> MotionModel:
        """The model of the same drift run backwards in time: a float filtered from its end
        towards its launch moves with the velocity negated and against the mean current
        (for a stationary velocity process, its time reversal is the same process)."""

    @abstractmethod
    def transition(self, dt_days: float) -> LinearGaussian:
        """A(dt), b(dt) and the noise factor L(dt) of the exact transition over `dt_days` (>= 0)."""

    def components(self, dt_days: float) -> list[tuple[float, LinearGaussian]]:
        """The transition as a mixture of linear-Gaussian kernels (probability, kernel); one
        kernel for the plain models, more for a mixture such as `JumpMixture`."""
        return [(1.0, self.transition(dt_days))]

    def origin_states(self, particles: Particles) -> NDArray[np.float64]:
        """Tangent-plane states (P, d) of particles, each at the origin of its own plane:
        position (0, 0), then the velocity if the model has one."""
        state = np.zeros((len(particles), self.dim))
        if self.has_velocity:
            if particles.velocity_km_per_day is None:
                raise ValueError(f"motion model {self.name!r} needs particles with a velocity")
            state[:, 2:] = particles.velocity_km_per_day
        return state

    def plane_states(self, now: Particles, nxt: Particles) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Tangent-plane states (P, d) of `now` (at the origin) and of `nxt` (its offset from
        `now` in `now`'s tangent plane), particle by particle, with velocities if any."""
        origin = self.origin_states(now)
        offset = origin.copy()
        offset[:, 0], offset[:, 1] = local_offsets_km(nxt.lat, nxt.lon, now.lat, now.lon)
        if self.has_velocity:
            if nxt.velocity_km_per_day is None:
                raise ValueError(f"motion model {self.name!r} needs particles with a velocity")
            offset[:, 2:] = nxt.velocity_km_per_day
        return origin, offset

    def log_transition(self, now: Particles, nxt: Particles, dt_days: float) -> NDArray[np.float64]:
        """log f(nxt_p | now_p, dt) for each particle p (the mixture over `components`)."""
        a, b = self.plane_states(now, nxt)
        terms = [np.log(w) + k.log_density(a, b) for w, k in self.components(max(dt_days, 0.0)) if w > 0]
        return np.logaddexp.reduce(np.array(terms), axis=0)

    def log_carried_transition(self, now: Particles, nxt: Particles, dt_days: float) -> NDArray[np.float64]:
        """log density of the part of the transition that a data-driven proposal does not
        redraw but carries over from the motion's own draw (the float clock of
        `clock.ClockWalk`); zero for a drift model alone."""
        return np.zeros(len(now))

    def stationary_velocity(self) -> tuple[NDArray[np.float64], float]:
        """Mean (east, north) and per-axis sd (km/day) of the velocity a freshly launched
        float is given; only for models with velocity."""
        raise NotImplementedError(f"motion model {self.name!r} has no velocity")

    def log_invariant_density(self, particles: Particles) -> NDArray[np.float64]:
        """log gamma(x) (up to a constant) of the law the drift leaves invariant and is
        reversible under: flat in position, the stationary law of the velocity (if any),
        N(v; mean, sd^2 I). gamma(x) f(x' | x) = gamma(x') f_rev(x | x') with f_rev
        the `reversed` model's transition: the two-filter smoother's artificial prior
        (`rafostrack.smoothing.two_filter`)."""
        if not self.has_velocity:
            return np.zeros(len(particles))
        if particles.velocity_km_per_day is None:
            raise ValueError(f"motion model {self.name!r} needs particles with a velocity")
        mean, sd = self.stationary_velocity()
        z = (particles.velocity_km_per_day - mean) / sd
        return -0.5 * np.einsum("pk,pk->p", z, z) - 2.0 * np.log(sd) - np.log(2.0 * np.pi)

    def stationary_velocities(self, n: int, rng: np.random.Generator) -> NDArray[np.float64] | None:
        """n velocities (n, 2) drawn from the stationary law (`stationary_velocity`); None
        for a model without velocity (and no draw)."""
        if not self.has_velocity:
            return None
        mean, sd = self.stationary_velocity()
        return np.ascontiguousarray((mean[:, None] + sd * rng.standard_normal((2, n))).T)

    def initial(self, lat: float, lon: float, sd_km: float, n: int, rng: np.random.Generator) -> Particles:
        """n particles about a position fix with sd `sd_km` per axis; a velocity, where the
        model has one, drawn from its stationary law (position draws first, then velocity)."""
        east, north = rng.normal(0.0, sd_km, size=(2, n))
        new_lat, new_lon = displace(np.full(n, lat), np.full(n, lon), east, north)
        velocity = self.stationary_velocities(n, rng)
        return Particles(np.clip(new_lat, -_MAX_LAT, _MAX_LAT), new_lon, velocity)

    def step(self, particles: Particles, dt_days: float, noise: NDArray[np.float64]) -> Particles:
        """The transition with given standard-normal `noise` (shape (dim, P)): deterministic,
        so a simulator can reuse the same noise (e.g. to bridge a track to an end fix)."""
        tr = self.transition(max(dt_days, 0.0))
        state = np.ascontiguousarray(self.origin_states(particles).T)
        # No BLAS: einsum's own loops give the same bits whatever the thread count.
        moved = np.einsum("ij,jp->ip", tr.A, state) + tr.b[:, None] + np.einsum("ij,jp->ip", tr.L, noise)
        return from_plane_states(particles, moved.T, self.has_velocity)

    def propagate(self, particles: Particles, dt_days: float, rng: np.random.Generator) -> Particles:
        """Sample x' ~ f(. | x, dt) for every particle (exact over any `dt_days`)."""
        return self.step(particles, dt_days, rng.standard_normal((self.dim, len(particles))))


@dataclass(frozen=True)
class JumpMixture(MotionModel):
    """A drift model made robust: with probability eps(dt) = 1 - exp(-rate dt) the float
    makes a move the base model cannot explain (carried by a current the model does not
    know, or a lost track), modelled as a broad jump:

        f(x' | x, dt) = (1 - eps) f_base(x' | x, dt) + eps g(x' | x),
        g: position x + N(0, R^2 I), velocity (if any) from the base's stationary law.

    The jump keeps the posterior from being certain of the impossible: when later arrival
    times fit nowhere near the drift model's prediction, particles re-seeded where they do
    fit (`rafostrack.filtering.recovery`) have a prior density to be weighted by, and the smoother
    can join a recovered track to what came before.
    """

    base: MotionModel
    jump_rate_per_day: float
    jump_sd_km: float

    @property
    def name(self) -> str:  # type: ignore[override]
        return self.base.name

    @property
    def has_velocity(self) -> bool:  # type: ignore[override]
        return self.base.has_velocity

    @classmethod
    def from_config(cls, cfg: MotionConfig) -> MotionModel:
        raise TypeError("JumpMixture wraps a configured model: build it with JumpMixture(base, rate, sd)")

    def transition(self, dt_days: float) -> LinearGaussian:
        """The base model's transition (the component without a jump)."""
        return self.base.transition(dt_days)

    def reversed(self) -> MotionModel:
        return JumpMixture(self.base.reversed(), self.jump_rate_per_day, self.jump_sd_km)

    def stationary_velocity(self) -> tuple[NDArray[np.float64], float]:
        return self.base.stationary_velocity()

    def jump_probability(self, dt_days: float) -> float:
        return float(-np.expm1(-self.jump_rate_per_day * max(dt_days, 0.0)))

    @functools.cached_property
    def jump(self) -> LinearGaussian:
        """g: position + N(0, R^2 I); velocity replaced by a stationary draw (made once)."""
        r = self.jump_sd_km
        if not self.has_velocity:
            return LinearGaussian(A=np.eye(2), b=np.zeros(2), L=r * np.eye(2))
        mean, sd = self.stationary_velocity()
        return LinearGaussian(
            A=np.diag([1.0, 1.0, 0.0, 0.0]), b=np.concatenate([[0.0, 0.0], mean]), L=np.diag([r, r, sd, sd])
        )

    def components(self, dt_days: float) -> list[tuple[float, LinearGaussian]]:
        eps = self.jump_probability(dt_days)
        return [(1.0 - eps, self.base.transition(dt_days)), (eps, self.jump)]

    def initial(self, lat: float, lon: float, sd_km: float, n: int, rng: np.random.Generator) -> Particles:
        return self.base.initial(lat, lon, sd_km, n, rng)

    def propagate(self, particles: Particles, dt_days: float, rng: np.random.Generator) -> Particles:
        """The base transition, then each particle replaced by a jump with probability eps."""
        moved = self.base.propagate(particles, dt_days, rng)
        jumps = np.flatnonzero(rng.random(len(particles)) < self.jump_probability(dt_days))
        if len(jumps) == 0:
            return moved
        jumped = _Kernel(self.jump, self.has_velocity).step(particles.take(jumps), rng)
        return moved.replace_at(jumps, jumped)


@dataclass(frozen=True)
class _Kernel:
    """Sampling from one linear-Gaussian kernel (used for the jump component)."""

    kernel: LinearGaussian
    has_velocity: bool

    def step(self, particles: Particles, rng: np.random.Generator) -> Particles:
        tr, n = self.kernel, len(particles)
        state = np.zeros((tr.dim, n))
        if self.has_velocity and particles.velocity_km_per_day is not None:
            state[2:] = particles.velocity_km_per_day.T
        moved = np.einsum("ij,jp->ip", tr.A, state) + tr.b[:, None]
        moved += np.einsum("ij,jp->ip", tr.L, rng.standard_normal((tr.dim, n)))
        return from_plane_states(particles, moved.T, self.has_velocity)
