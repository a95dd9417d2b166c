"""A backward pass as a guide for the forward one: both ends of the record inform every window.

A forward filter knows the past: when it lost a float (a mirror image across two sources, a
jump during a gap it never re-acquired in time), smoothing its particles cannot bring back a
position it never held. A filter run backwards from the recovery fix knows the future, and
fails, if at all, elsewhere. Run it first; then filter forwards with part of each window's
particles proposed from the backward cloud of that window (a Gaussian kernel density of it,
`CloudProposal`), weighted by multiple importance sampling against the drift model
(`filter.ParticleFilter._mix`). Where both directions agree, the guided particles change
nothing (their weights are those of any particle there); where the forward filter was about
to lose the float, they keep the position the later data support alive, and the smoother,
with the whole record, decides.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .domain import Cloud, Particles, Window
from .filter import Observation, Proposal, Step
from .geodesy import displace, local_offsets_km
from .smoother import cloud_covariance, silverman_bandwidth

N_COMPONENTS = 64


@dataclass(frozen=True)
class CloudProposal:
    """A Gaussian kernel density over M components of a weighted cloud: equal weights, kernel
    covariance h^2 Sigma (Sigma the cloud's covariance, h Silverman's bandwidth for M), in
    each component's tangent plane; velocities (if any) are part of the kernel."""

    lat: NDArray[np.float64]
    lon: NDArray[np.float64]
    velocity: NDArray[np.float64] | None
    chol: NDArray[np.float64]  # (d, d), lower triangular: the kernel covariance is chol chol^T

    def sample(self, n: int, rng: np.random.Generator) -> Particles:
        pick = rng.integers(0, len(self.lat), size=n)
        z = rng.standard_normal((n, self.chol.shape[0])) @ self.chol.T
        lat, lon = displace(self.lat[pick], self.lon[pick], z[:, 0], z[:, 1])
        velocity = None if self.velocity is None else self.velocity[pick] + z[:, 2:]
        return Particles(lat, lon, velocity)

    def log_density(self, particles: Particles) -> NDArray[np.float64]:
        d = self.chol.shape[0]
        log_norm = -np.log(len(self.lat)) - np.log(np.diag(self.chol)).sum() - 0.5 * d * np.log(2.0 * np.pi)
        terms = np.empty((len(self.lat), len(particles)))
        for m in range(len(self.lat)):
            east, north = local_offsets_km(particles.lat, particles.lon, self.lat[m], self.lon[m])
            cols = [east, north]
            if self.velocity is not None and particles.velocity_km_per_day is not None:
                cols += list((particles.velocity_km_per_day - self.velocity[m]).T)
            y = np.linalg.solve(self.chol, np.array(cols))  # whitened offsets (d, P)
            terms[m] = -0.5 * np.einsum("dp,dp->p", y, y)
        return np.logaddexp.reduce(terms, axis=0) + log_norm


def cloud_proposal(cloud: Cloud, *, reverse_velocity: bool = False, n_components: int = N_COMPONENTS) -> CloudProposal:
    """The kernel density of `cloud` (velocities negated with `reverse_velocity`, for a cloud
    of a backward filter), over `n_components` particles picked systematically by weight."""
    w = cloud.weights / cloud.weights.sum()
    cumulative = np.cumsum(w)
    cumulative[-1] = 1.0
    pick = np.searchsorted(cumulative, (np.arange(n_components) + 0.5) / n_components, side="right")
    particles = cloud.particles.take(pick)
    if reverse_velocity:
        particles = particles.reversed()
    spread = cloud_covariance(Cloud(cloud.time, cloud.particles, w))
    if reverse_velocity and spread.shape[0] == 4:  # negating velocity flips the position-velocity terms
        flip = np.diag([1.0, 1.0, -1.0, -1.0])
        spread = flip @ spread @ flip
    h = silverman_bandwidth(n_components, spread.shape[0])
    floor = np.diag([0.25, 0.25] + [0.04] * (spread.shape[0] - 2))  # 0.5 km, 0.2 km/day
    chol = np.asarray(np.linalg.cholesky(h * h * spread + floor), dtype=np.float64)
    return CloudProposal(particles.lat, particles.lon, particles.velocity_km_per_day, chol)


class BackwardGuide:
    """Per forward observation, a proposal from the backward filter's cloud at that window."""

    def __init__(self, backward_steps: Sequence[Step], fraction: float):
        self.fraction = fraction
        self._clouds = {
            s.cloud.time: s.cloud for s in backward_steps if isinstance(s.observation, Window) and s.ess > 1.5
        }

    def __call__(self, obs: Observation) -> list[tuple[float, Proposal]]:
        cloud = self._clouds.get(obs.time) if isinstance(obs, Window) else None
        if cloud is None:
            return []
        return [(self.fraction, cloud_proposal(cloud, reverse_velocity=True))]
