"""A float's leg fit: the leg posterior and what it was fitted to (`floats.fit_legs` makes
it, `outputs` writes it)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..domain import Window
from ..run.method import TrackOutput
from .evidence import FloatEvidence
from .model import LegPrior, Legs
from .plane import Plane
from .sampler import Chain


@dataclass(frozen=True)
class LegFit:
    """A float's leg posterior and what it was fitted to (times in days since `epoch`)."""

    float_id: str
    epoch: np.datetime64
    plane: Plane
    windows: tuple[Window, ...]
    window_days: NDArray[np.float64]
    evidence: FloatEvidence
    chain: Chain
    start: Legs
    prior: LegPrior
    smoother: TrackOutput
    timings: dict[str, float]
