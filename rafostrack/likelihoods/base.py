"""The likelihood-component interface: what one kind of evidence says about each particle.

A component turns one observation (a listening window, a position fix, later a context
grid) into per-particle log-likelihoods log p(y | x_p), plus, for arrival windows, the
association marginals P(signal j from beacon i | x_p) and any warnings met on the way. The
filter multiplies the components' likelihoods into the weights; it knows nothing else
about them.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..domain import Particles

# A Gaussian observation (a hand-labelled TOA, a position fix) farther than OUTLIER_SD sd
# from every particle is one no particle explains: its weights would collapse the cloud
# onto the single nearest particle. Its sd is widened so that the nearest particle sits at
# RECOVER_SD sd, and a warning is recorded.
OUTLIER_SD = 6.0
RECOVER_SD = 3.0


def outlier_scale(z_nearest: NDArray | float) -> NDArray:
    """Factor widening an observation's sd: z / RECOVER_SD where the nearest particle is
    z > OUTLIER_SD sd away, else 1."""
    z = np.asarray(z_nearest, dtype=float)
    return np.where(z > OUTLIER_SD, z / RECOVER_SD, 1.0)


@dataclass(frozen=True)
class Evidence:
    """Per-particle log p(y | x) of one observation, and what came with it."""

    loglik: NDArray[np.float64]  # (P,)
    beacon_index: NDArray[np.intp] = field(default_factory=lambda: np.zeros(0, dtype=np.intp))  # (s,) table rows
    p_match: NDArray[np.float64] | None = None  # (P, s, K) association marginals, if any
    warnings: tuple[str, ...] = ()  # each a `Notice`, its kind set by the component that makes it


class Likelihood(ABC):
    """log p(y | x) for one kind of observation."""

    @abstractmethod
    def evaluate(self, particles: Particles, observation: Any, *, marginals: bool = True) -> Evidence:
        """Evidence of `observation` for every particle; `marginals=False` is a hint that
        association marginals are not wanted (they may then be NaN)."""


class MoveFactor(ABC):
    """A factor on each particle's move between two observations: log g(x_prev, x) for the
    states before and after the motion step at `observation` (e.g. a context constraint
    applied when a particle enters a new cell of a context grid). The filter adds it to the
    log-weights beside the observation's likelihood."""

    @abstractmethod
    def log_weight(self, before: Particles, after: Particles, observation: Any) -> NDArray[np.float64]:
        """log g per particle (0 where the factor does not apply)."""

    def regions(self, particles: Particles) -> NDArray[np.int64] | None:
        """Labels of the regions the particles are in, where regions are parted by ground the
        factor forbids (a posterior on both sides of a ridge has two modes, whose mean lies on
        the ridge); None when the factor parts nothing."""
        return None
