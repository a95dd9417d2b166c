"""A proposal guided by the window: each drift prior updated by a Gaussian summary of the window's likelihood.

The locally optimal proposal q(x' | x_i, T) ~ f(x' | x_i) p(T | x') (Doucet, Godsill &
Andrieu 2000, "On sequential Monte Carlo sampling methods for Bayesian filtering", sec.
II-D) cannot be sampled for the ranked likelihood of a window's arrival times T. Its
Gaussian stand-in:

1. Summary (`summarise_likelihood`). The cloud moved by the drift model (x'_p ~ f(. | x_p))
   and weighted by the window's likelihood is a pilot. A quadratic in the position y
   (east/north km in a tangent plane at the pilot's heaviest particle) is fitted to
   log p(T | x'_p) by least squares, weighted by the pilot's posterior weights, so it
   describes the likelihood where the posterior is:

       log p(T | y) ~ c + eta' y - y' Lambda y / 2,

   Lambda's eigenvalues floored at zero (a direction the window does not sharpen is
   left to the drift, and eta has no part along it).
2. Proposal (`GuidedDrift`). For particle i, the drift is x' = A x_i + b + e, e ~ N(0, Q)
   in its own tangent plane (`motion.base.LinearGaussian`; positions km, velocities
   km/day), and its position in the summary's plane is y = H x' + o_i (H picks the
   position, o_i is the particle's origin in that plane). f(x' | x_i) exp(eta' y -
   y' Lambda y / 2) is Gaussian, with the same covariance for every particle,

       C = (Q^-1 + H' Lambda H)^-1 = Q - (R H Q)' (I + R H Q H' R)^-1 (R H Q),  R = Lambda^(1/2)

   (a form with no inverse of Lambda, which is singular when the window sharpens one
   direction only), and mean

       m'_i = m_i + C H' (eta - Lambda o_i - Lambda H m_i),   m_i = A x_i + b:

   one Kalman update of the drift prior by a pseudo-observation of the position.

The filter draws each particle from the defensive mixture alpha_0 f(. | x_i) + alpha_1 q_i
and weights it by the mixture (`ParticleFilter._mix`, balance heuristic), so the weights
are exact whatever the summary: where the likelihood is not Gaussian (two modes, a wrong
association), the drift's own draws keep the posterior right and the guided ones only
cost their evaluation. The pilot's draws are kept as the drift component's draws; the
summary depends on each of them only through a fit to all of them. What it buys and costs
on the benchmarks (more ESS, the same accuracy, more time; off by default): docs/decisions.md.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import solve_triangular

from ..domain import Particles
from ..model.geodesy import local_offsets_km
from ..motion import LinearGaussian, MotionModel
from ..motion.base import from_plane_states
from .resampling import ess, normalise_log_weights

# A quadratic has 6 coefficients in 2-d; fitted on fewer effective particles than this,
# the summary is noise, and the window is left to the drift model.
MIN_PILOT_ESS = 30.0


@dataclass(frozen=True)
class LikelihoodSummary:
    """log p(T | y) ~ c + eta' y - y' Lambda y / 2, y the position (km) in the tangent
    plane at (lat0, lon0)."""

    lat0: float
    lon0: float
    precision: NDArray[np.float64]  # Lambda (2, 2), positive semi-definite, 1/km^2
    shift: NDArray[np.float64]  # eta (2,), 1/km


def summarise_likelihood(
    moved: Particles, prior_weights: NDArray, loglik: NDArray, min_ess: float = MIN_PILOT_ESS
) -> LikelihoodSummary | None:
    """The window's likelihood as a Gaussian in position (module docstring, step 1): the
    posterior-weighted least-squares quadratic fit of `loglik` over the pilot's positions.
    None when the pilot's posterior ESS is under `min_ess` or the window sharpens nothing."""
    finite = np.isfinite(loglik) & (prior_weights > 0)
    if finite.sum() < min_ess:
        return None
    with np.errstate(divide="ignore"):
        post, _ = normalise_log_weights(np.where(finite, np.log(prior_weights) + loglik, -np.inf))
    if ess(post) < min_ess:
        return None
    top = int(np.argmax(post))
    lat0, lon0 = float(moved.lat[top]), float(moved.lon[top])
    east, north = local_offsets_km(moved.lat[finite], moved.lon[finite], lat0, lon0)
    w = np.sqrt(post[finite])
    features = np.column_stack([np.ones_like(east), east, north, east * east, east * north, north * north])
    coef, *_ = np.linalg.lstsq(features * w[:, None], loglik[finite] * w, rcond=None)
    hessian = -np.array([[2.0 * coef[3], coef[4]], [coef[4], 2.0 * coef[5]]])
    values, vectors = np.linalg.eigh(hessian)
    sharpened = values > 0.0
    if not sharpened.any():
        return None
    precision = (vectors * np.where(sharpened, values, 0.0)) @ vectors.T
    along = vectors[:, sharpened] @ vectors[:, sharpened].T
    return LikelihoodSummary(lat0, lon0, precision, along @ coef[1:3])


@dataclass(frozen=True)
class GuidedDrift:
    """q_i(x' | x_i): the drift prior of each particle updated by a `LikelihoodSummary`
    (module docstring, step 2); a `filter.Proposal`."""

    motion: MotionModel
    dt_days: float
    summary: LikelihoodSummary

    @functools.cached_property
    def _transition(self) -> LinearGaussian:
        return self.motion.transition(self.dt_days)

    @functools.cached_property
    def _covariance(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """What every particle shares: the gain C H' and the Cholesky factor of C."""
        q, lam = self._transition.Q, self.summary.precision
        values, vectors = np.linalg.eigh(lam)
        root = (vectors * np.sqrt(np.maximum(values, 0.0))) @ vectors.T
        rhq = root @ q[:2, :]
        inner = np.eye(2) + rhq[:, :2] @ root
        cov = q - rhq.T @ np.linalg.solve(inner, rhq)
        cov = 0.5 * (cov + cov.T)
        return cov[:, :2], np.linalg.cholesky(cov)

    def _means(self, ancestors: Particles) -> NDArray[np.float64]:
        """The means m'_i (P, d), each in its ancestor's plane."""
        tr = self._transition
        mean = self.motion.origin_states(ancestors) @ tr.A.T + tr.b
        east, north = local_offsets_km(ancestors.lat, ancestors.lon, self.summary.lat0, self.summary.lon0)
        lam = self.summary.precision
        innovation = self.summary.shift - (np.column_stack([east, north]) + mean[:, :2]) @ lam
        return mean + innovation @ self._covariance[0].T

    def sample(self, ancestors: Particles, rng: np.random.Generator) -> Particles:
        """One draw x' ~ q_i for each ancestor x_i."""
        mean, factor = self._means(ancestors), self._covariance[1]
        state = mean + rng.standard_normal(mean.shape) @ factor.T
        return from_plane_states(ancestors, state, self.motion.has_velocity)

    def log_density(self, ancestors: Particles, particles: Particles) -> NDArray[np.float64]:
        """log q_i(x'_i) of each particle given its ancestor."""
        mean, factor = self._means(ancestors), self._covariance[1]
        _, state = self.motion.plane_states(ancestors, particles)
        z = solve_triangular(factor, (state - mean).T, lower=True)
        d = mean.shape[1]
        log_det = float(np.sum(np.log(np.diag(factor))))
        return -0.5 * np.einsum("kp,kp->p", z, z) - log_det - 0.5 * d * np.log(2.0 * np.pi)


@dataclass(frozen=True)
class Guide:
    """When and how much to guide: `fraction` of the particles are drawn from `GuidedDrift`
    at each window whose pilot supports a summary (`summarise_likelihood`)."""

    fraction: float
    min_pilot_ess: float = MIN_PILOT_ESS

    def proposal(
        self, motion: MotionModel, dt_days: float, moved: Particles, prior_weights: NDArray, loglik: NDArray
    ) -> GuidedDrift | None:
        """The proposal for a window `dt_days` after the last step, from the pilot `moved`
        (the cloud moved by `motion`, its `prior_weights`, the window's `loglik`); None when
        there is no interval to guide over or no summary (`summarise_likelihood`)."""
        if dt_days <= 0.0:
            return None
        summary = summarise_likelihood(moved, prior_weights, loglik, self.min_pilot_ess)
        return None if summary is None else GuidedDrift(motion, dt_days, summary)
