"""Inference engines for the window's association sum (see `base`).

`ENGINES` maps the config's `[filter] engine` to the engine module's `from_config`:
`exact` (dynamic programming over subsets of signals) and `bp` (loopy belief
propagation, Bethe estimate). To add one, see ARCHITECTURE.md.
"""

from __future__ import annotations

from ..config import Config
from . import bp, exact
from .base import Association, Engine, EngineFactory

ENGINES: dict[str, EngineFactory] = {"exact": exact.from_config, "bp": bp.from_config}


def engine_from_config(config: Config) -> Engine:
    """The configured engine (`[filter] engine`)."""
    return ENGINES[config.filter.engine](config)


__all__ = ["ENGINES", "Association", "Engine", "EngineFactory", "bp", "engine_from_config", "exact"]
