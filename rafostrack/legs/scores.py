"""Scores and likelihoods of position measurements given a leg trajectory.

Each likelihood holds measurements y_j at times t_j and gives per-measurement log
terms log p(y_j | z(t_j)) for trajectory positions z, so that a sampler move that
changes only part of the trajectory recomputes only the terms it changes.

- `paper_score`: the paper's score (section 4.2), the summed Euclidean distance
  S = sum_j |z(t_j) - y_j|, smaller is better;
- `PaperScoreLikelihood`: how the paper's MCMC toolbox turns a score into a likelihood,
  L = exp(-S / (2 sigma^2)) (its `ssfun` / `sigma2` convention), sigma^2 the measurement
  variance given to the sampler; a Laplace-like, heavy-tailed likelihood in |r|;
- `GaussianLikelihood`: y_j ~ N(z(t_j), sd^2 I) (ours: the proper likelihood for the paper's
  noise model);
- `StudentLikelihood`: y_j ~ bivariate Student-t(nu) with scale sd (ours: heavy tails).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.special import gammaln


def paper_score(estimate_xy: NDArray, measured_xy: NDArray) -> float:
    """The paper's score: sum_j |z_j - y_j| (Euclidean)."""
    r = np.asarray(estimate_xy) - np.asarray(measured_xy)
    return float(np.hypot(r[:, 0], r[:, 1]).sum())


@dataclass(frozen=True)
class Measurements:
    """Position measurements: times (n,) ascending and positions (n, 2)."""

    times: NDArray[np.float64]
    xy: NDArray[np.float64]

    def __post_init__(self) -> None:
        if self.xy.shape != (len(self.times), 2):
            raise ValueError(f"xy must be ({len(self.times)}, 2), got {self.xy.shape}")
        if np.any(np.diff(self.times) < 0):
            raise ValueError("measurement times must be ascending")


@dataclass(frozen=True)
class GaussianLikelihood:
    """log N(y_j; z_j, sd^2 I) per measurement."""

    data: Measurements
    sd: float

    @property
    def times(self) -> NDArray[np.float64]:
        return self.data.times

    def terms(self, xy: NDArray, index: slice) -> NDArray[np.float64]:
        r = xy - self.data.xy[index]
        return -0.5 * (r[:, 0] ** 2 + r[:, 1] ** 2) / self.sd**2 - math.log(2 * math.pi * self.sd**2)


@dataclass(frozen=True)
class StudentLikelihood:
    """Bivariate Student-t: log p = log G((nu+2)/2) - log G(nu/2) - log(nu pi sd^2)
    - (nu+2)/2 log(1 + |r|^2 / (nu sd^2))."""

    data: Measurements
    sd: float
    dof: float = 4.0

    @property
    def times(self) -> NDArray[np.float64]:
        return self.data.times

    def terms(self, xy: NDArray, index: slice) -> NDArray[np.float64]:
        r = xy - self.data.xy[index]
        nu, s2 = self.dof, self.sd**2
        const = gammaln((nu + 2) / 2) - gammaln(nu / 2) - math.log(nu * math.pi * s2)
        return const - (nu + 2) / 2 * np.log1p((r[:, 0] ** 2 + r[:, 1] ** 2) / (nu * s2))


@dataclass(frozen=True)
class PaperScoreLikelihood:
    """The paper's score as its sampler used it: log L = -S / (2 sigma^2), per measurement -|r_j| / (2 sigma^2)."""

    data: Measurements
    sigma2: float

    @property
    def times(self) -> NDArray[np.float64]:
        return self.data.times

    def terms(self, xy: NDArray, index: slice) -> NDArray[np.float64]:
        r = xy - self.data.xy[index]
        return -np.hypot(r[:, 0], r[:, 1]) / (2.0 * self.sigma2)
