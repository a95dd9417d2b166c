"""Inference engines for the window's association sum (see `base`).

`ENGINES` maps the config's `[filter] engine` to the engine module's `from_config`:
`exact` (dynamic programming over subsets of signals), `bp` (loopy belief
propagation, Bethe estimate) and `abc` (approximate Bayesian computation from simulated
windows: a `SimulatingEngine`, called with the window rather than the factors). To add
one, see ARCHITECTURE.md.
"""

from __future__ import annotations

from ..config import Config
from . import abc, bp, exact
from .base import Association, Engine, EngineFactory, SimulatingEngine, WindowPrediction

ENGINES: dict[str, EngineFactory] = {"exact": exact.from_config, "bp": bp.from_config, "abc": abc.from_config}


def engine_from_config(config: Config) -> Engine | SimulatingEngine:
    """The configured engine (`[filter] engine`)."""
    return ENGINES[config.filter.engine](config)


__all__ = [
    "ENGINES",
    "Association",
    "Engine",
    "EngineFactory",
    "SimulatingEngine",
    "WindowPrediction",
    "abc",
    "bp",
    "engine_from_config",
    "exact",
]
