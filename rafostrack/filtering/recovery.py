"""Lost-track recovery: where do this window's arrival times fit, whatever the drift model says?

An analyst who has lost a float in ARTOA multilaterates: takes the stored arrival times,
tries which sources they could come from, and finds the positions that fit. The same, with
the model's own likelihood: `CandidateSearch` evaluates the window's likelihood
p(T | X) (association summed out, clutter and misses included) on a grid around the
particle cloud, coarse first (with the TOA noise widened by the grid's resolution, so no
peak falls between nodes), then finely around the best coarse cells. The result is every
position where the window fits, mirror images included, with its log-likelihood.

`Reseeding` turns the candidates into a proposal q(x) (a Gaussian mixture over the best
fine nodes, velocities from the motion model's stationary law) whose density can be
evaluated, so that re-seeded particles are weighted correctly against the motion model
(including its jump component, `motion.JumpMixture`): with probability `fraction` a
particle's new state is drawn from q instead of the motion model, and every particle's
weight is divided by the mixture (1 - fraction) f(x' | x) + fraction q(x') (multiple
importance sampling, balance heuristic). When the drift model's prediction fits, the
re-seeded particles carry negligible weight and the posterior is unchanged; when it does
not, they take over.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..domain import Particles, Window
from ..likelihoods import ArrivalLikelihood
from ..model.geodesy import displace, local_offsets_km
from ..motion import MotionModel
from .resampling import log_sum_exp

KM_PER_S = 1.48  # travel distance per second of arrival time, for sizing the grids


@dataclass(frozen=True)
class Candidates:
    """Positions where a window's arrival times fit, and their log-likelihoods."""

    lat: NDArray[np.float64]
    lon: NDArray[np.float64]
    loglik: NDArray[np.float64]

    @property
    def best(self) -> float:
        return float(self.loglik.max()) if len(self.loglik) else -np.inf


@functools.lru_cache(maxsize=16)
def _disc(radius_km: float, step_km: float) -> tuple[NDArray, NDArray]:
    """East/north offsets of a square grid of spacing `step_km` inside a disc (read-only:
    made once per grid, every search uses the same two)."""
    k = np.arange(-np.floor(radius_km / step_km), np.floor(radius_km / step_km) + 1) * step_km
    east, north = np.meshgrid(k, k)
    inside = east**2 + north**2 <= radius_km**2
    east, north = east[inside], north[inside]
    for offsets in (east, north):
        offsets.setflags(write=False)
    return east, north


def _non_max_suppression(east: NDArray, north: NDArray, score: NDArray, k: int, min_km: float) -> NDArray[np.intp]:
    """Indices of up to k best points, each at least `min_km` from every better one kept."""
    kept: list[int] = []
    for i in np.argsort(score)[::-1]:
        if not np.isfinite(score[i]):
            break
        if all(np.hypot(east[i] - east[j], north[i] - north[j]) >= min_km for j in kept):
            kept.append(int(i))
            if len(kept) == k:
                break
    return np.array(kept, dtype=np.intp)


@dataclass(frozen=True)
class CandidateSearch:
    """Grid search of a window's likelihood around a position (module docstring)."""

    arrivals: ArrivalLikelihood
    radius_km: float = 150.0
    coarse_km: float = 8.0
    fine_km: float = 1.5
    n_peaks: int = 6

    @functools.cached_property
    def _widened(self) -> ArrivalLikelihood:
        """The likelihood of the coarse grid: the TOA noise sd widened by its resolution."""
        return self.arrivals.with_toa_sigma(
            float(np.hypot(self.arrivals.model.toa_sigma_s, self.coarse_km / (2.0 * KM_PER_S)))
        )

    def search(self, lat0: float, lon0: float, window: Window, clock_s: float | None = None) -> Candidates:
        """Every fine-grid position around the best coarse peaks within `radius_km` of
        (lat0, lon0), with its exact window log-likelihood (at the float clock correction
        `clock_s` where the clock is part of the state)."""
        if window.n_signals == 0:
            return Candidates(np.zeros(0), np.zeros(0), np.zeros(0))
        east, north = _disc(self.radius_km, self.coarse_km)
        lat, lon = displace(np.full(len(east), lat0), np.full(len(east), lon0), east, north)
        coarse = self._widened.evaluate(_at_clock(lat, lon, clock_s), window, marginals=False).loglik
        peaks = _non_max_suppression(east, north, coarse, self.n_peaks, 2.0 * self.coarse_km)
        fe, fn = _disc(self.coarse_km, self.fine_km)
        e = (east[peaks][:, None] + fe[None, :]).ravel()
        n = (north[peaks][:, None] + fn[None, :]).ravel()
        lat, lon = displace(np.full(len(e), lat0), np.full(len(e), lon0), e, n)
        loglik = self.arrivals.evaluate(_at_clock(lat, lon, clock_s), window, marginals=False).loglik
        return Candidates(lat, lon, loglik)


def _at_clock(lat: NDArray, lon: NDArray, clock_s: float | None) -> Particles:
    """Search nodes as particles, all at the float clock correction `clock_s` (if any)."""
    return Particles(lat, lon, clock_s=None if clock_s is None else np.full(len(lat), clock_s))


@dataclass(frozen=True)
class Reseeding:
    """A proposal from search candidates: a Gaussian mixture over the nodes within
    `keep_nats` of the best, each weighted by its likelihood, sd `sd_km` per axis;
    velocities from the motion model's stationary law."""

    candidates: Candidates
    motion: MotionModel
    sd_km: float = 1.5
    keep_nats: float = 12.0

    def _mixture(self) -> tuple[NDArray, NDArray, NDArray]:
        c = self.candidates
        keep = c.loglik >= c.best - self.keep_nats
        log_pi = c.loglik[keep] - log_sum_exp(c.loglik[keep])
        return c.lat[keep], c.lon[keep], log_pi

    def sample(self, ancestors: Particles, rng: np.random.Generator) -> Particles:
        """One draw per ancestor, whatever the ancestor."""
        n = len(ancestors)
        lat_c, lon_c, log_pi = self._mixture()
        pick = rng.choice(len(log_pi), size=n, p=np.exp(log_pi))
        east, north = rng.normal(0.0, self.sd_km, size=(2, n))
        lat, lon = displace(lat_c[pick], lon_c[pick], east, north)
        return Particles(lat, lon, self.motion.stationary_velocities(n, rng))

    def log_density(self, ancestors: Particles, particles: Particles) -> NDArray[np.float64]:
        """log q(x, v) of each particle (position mixture times the velocity law), whatever
        its ancestor."""
        lat_c, lon_c, log_pi = self._mixture()
        s2 = self.sd_km**2
        terms = []
        for k in range(len(log_pi)):  # per component: numpy's vectorised sin and cos differ in the last bit
            east, north = local_offsets_km(particles.lat, particles.lon, lat_c[k], lon_c[k])
            terms.append(log_pi[k] - (east * east + north * north) / (2.0 * s2) - np.log(2.0 * np.pi * s2))
        # The velocity law is the drift's stationary one: its invariant density (flat in
        # position, zero for a model without velocity).
        return np.logaddexp.reduce(np.array(terms), axis=0) + self.motion.log_invariant_density(particles)


@dataclass(frozen=True)
class RecoverySettings:
    """When to look for a lost float, and how hard.

    A window is checked (`CandidateSearch` around the predicted cloud) after a gap of at
    least `gap_days` without windows, when its log evidence falls `drop_nats` below the
    median of the last `history` windows, when the ESS falls below `min_ess_fraction` of
    the particles, and every `check_every` windows regardless. Re-seeding happens when the
    best candidate beats the best particle by `min_gain_nats`: a fraction `fraction` of the
    particles is then drawn from the candidates."""

    search_radius_km: float = 150.0
    gap_days: float = 1.5
    drop_nats: float = 6.0
    min_ess_fraction: float = 0.02
    check_every: int = 10
    history: int = 15
    min_gain_nats: float = 3.0
    fraction: float = 0.25


class RecoveryMonitor:
    """Per run: decides, window by window, whether to search and re-seed (`RecoverySettings`)."""

    def __init__(self, settings: RecoverySettings, arrivals: ArrivalLikelihood, motion: MotionModel):
        self.settings = settings
        self.search = CandidateSearch(arrivals, radius_km=settings.search_radius_km)
        self.motion = motion
        self._evidence: list[float] = []
        self._since_check = 0
        self.n_checks = 0
        self.n_reseeds = 0

    def record(self, log_evidence: float) -> None:
        """The log evidence log p(y_t | y_1..t-1) of a window, once it is known."""
        if np.isfinite(log_evidence):
            self._evidence = [*self._evidence[-(self.settings.history - 1) :], log_evidence]

    def proposal(
        self,
        window: Window,
        gap_days: float,
        predicted: Particles,
        prior_weights: NDArray,
        loglik: NDArray,
    ) -> Reseeding | None:
        """A re-seeding proposal for this window, or None when the cloud fits (or no check is due).

        `predicted` are the particles moved by the motion model, `prior_weights` their
        weights before this window, `loglik` their log-likelihoods of it.
        """
        s = self.settings
        self._since_check += 1
        post = prior_weights * np.exp(loglik - loglik.max())
        post_ess = float(post.sum() ** 2 / np.einsum("p,p->", post, post)) if post.sum() > 0 else 0.0
        log_evidence = log_sum_exp(loglik, prior_weights)
        due = (
            gap_days >= s.gap_days
            or self._since_check >= s.check_every
            or post_ess < s.min_ess_fraction * len(loglik)
            or (len(self._evidence) >= 3 and log_evidence < float(np.median(self._evidence)) - s.drop_nats)
        )
        if not due or window.n_signals == 0:
            return None
        self._since_check = 0
        self.n_checks += 1
        centre = int(np.argmax(prior_weights))  # the predicted cloud's heaviest particle
        clock = None if predicted.clock_s is None else float(predicted.clock_s[centre])
        candidates = self.search.search(float(predicted.lat[centre]), float(predicted.lon[centre]), window, clock)
        if candidates.best - float(loglik.max()) < s.min_gain_nats:
            return None
        self.n_reseeds += 1
        return Reseeding(candidates, self.motion)
