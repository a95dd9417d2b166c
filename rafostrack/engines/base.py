"""The association-engine interface and its registry.

An engine computes, per particle, the window's association sum over partial matchings M
of beacons to signals (`rafostrack.model` gives the factors, log w of shape (P, s, K) and
log u of shape (P, s)):

    Z = sum_M prod_{(i,j) in M} w_ij prod_{i unmatched} u_i,

returning log Z and the marginal probability that signal j came from beacon i. Every
engine accepts `marginals=False`, a hint that only log Z is wanted (an engine may then
return NaN marginals). Each engine module has `from_config(config) -> Engine`; the
registry is `rafostrack.engines.ENGINES`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from ..config import Config


@dataclass(frozen=True)
class Association:
    log_z: NDArray[np.float64]  # (P,)
    p_match: NDArray[np.float64]  # (P, s, K): P(signal j from beacon i | X)

    @property
    def p_clutter(self) -> NDArray[np.float64]:
        """(P, K): probability that each signal is clutter."""
        return np.clip(1.0 - self.p_match.sum(axis=1), 0.0, 1.0)


class Engine(Protocol):
    def __call__(self, log_match: NDArray, log_unheard: NDArray, *, marginals: bool = True) -> Association: ...


EngineFactory = Callable[[Config], Engine]
