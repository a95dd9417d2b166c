"""Motion models: how a float drifts between windows (see `base.MotionModel`).

`MOTION_MODELS` maps the config's `[motion] model` to a model class; each class builds
itself from the `[motion]` section with `from_config`. To add one, see ARCHITECTURE.md.
"""

from __future__ import annotations

from ..config import MotionConfig
from .base import JumpMixture, LinearGaussian, MotionModel
from .clock import ClockWalk
from .ou import IntegratedOU
from .random_walk import RandomWalk

MOTION_MODELS: dict[str, type[MotionModel]] = {RandomWalk.name: RandomWalk, IntegratedOU.name: IntegratedOU}


def motion_from_config(cfg: MotionConfig) -> MotionModel:
    """The configured motion model."""
    return MOTION_MODELS[cfg.model].from_config(cfg)


__all__ = [
    "MOTION_MODELS",
    "ClockWalk",
    "IntegratedOU",
    "JumpMixture",
    "LinearGaussian",
    "MotionModel",
    "RandomWalk",
    "motion_from_config",
]
