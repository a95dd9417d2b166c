"""The association-engine interface and its registry.

An engine computes, per particle, the window's association sum over partial matchings M
of beacons to signals (`rafostrack.model.measurement` gives the factors, log w of shape (P, s, K) and
log u of shape (P, s)):

    Z = sum_M prod_{(i,j) in M} w_ij prod_{i unmatched} u_i,

returning log Z and the marginal probability that signal j came from beacon i. Every
engine accepts `marginals=False`, a hint that only log Z is wanted (an engine may then
return NaN marginals). Each engine module has `from_config(config) -> Engine`; the
registry is `rafostrack.engines.ENGINES`.

A *simulating* engine (`SimulatingEngine`, e.g. `abc`) does not take the factors: it needs
only a simulator of one window, so it receives the window itself (`WindowPrediction`: the
stored TOAs, each particle's predicted arrivals and detection probabilities, the model,
and the seed material of the window's random draws) and returns an `Association` whose
log_z is its estimate of the window's whole log-likelihood log p(T | X) (not only the
association sum: `RankedArrivals.evaluate` adds no shared term to it).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from ..config import Config, ModelConfig


@dataclass(frozen=True)
class Association:
    log_z: NDArray[np.float64]  # (P,)
    p_match: NDArray[np.float64]  # (P, s, K): P(signal j from beacon i | X), first arrival or echo
    p_echo: NDArray[np.float64] | None = None  # (P, s, K): P(signal j is beacon i's echo | X), if summed

    @property
    def p_clutter(self) -> NDArray[np.float64]:
        """(P, K): probability that each signal is clutter."""
        return np.clip(1.0 - self.p_match.sum(axis=1), 0.0, 1.0)


class Engine(Protocol):
    def __call__(
        self, log_match: NDArray, log_unheard: NDArray, *, marginals: bool = True, log_echo: NDArray | None = None
    ) -> Association: ...


@dataclass(frozen=True)
class WindowPrediction:
    """One window as a simulating engine sees it, for P particles and the s beacons of the
    window. `entropy` seeds the window's random draws: the engine derives its Generator
    from it (so the same float, seed and window give the same draws, whatever the order in
    which windows are evaluated)."""

    toa_s: NDArray[np.float64]  # (K,) stored arrival times, ascending
    mu_s: NDArray[np.float64]  # (P, s) predicted arrival times
    p_detect: NDArray[np.float64]  # (P, s) detection probabilities
    max_signals: int  # r: the float stores its earliest r signals
    window_s: float
    model: ModelConfig
    entropy: tuple[int, ...]  # (filter seed, crc32 of the float id, window time in ns mod 2^64)
    ranked: bool = True  # False: the unranked baseline (no storage limit in the simulation)


@runtime_checkable
class SimulatingEngine(Protocol):
    def simulate(self, window: WindowPrediction, *, marginals: bool = True) -> Association: ...


EngineFactory = Callable[[Config], Engine | SimulatingEngine]
