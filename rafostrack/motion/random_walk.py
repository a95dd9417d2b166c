"""Random-walk drift (paper eq. 1), optionally around a mean current.

    X_{t+dt} = X_t + vbar dt + (e, n),   e, n ~ N(0, D^2 dt),

with D = `diffusion_km_per_day` and dt in days, in the local east/north tangent plane of
each particle. Position only: no velocity persists from one window to the next, so the
spread after a gap of k days is D sqrt(k) per axis whatever the float was doing before.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from ..config import MotionConfig
from .base import LinearGaussian, MotionModel


@dataclass(frozen=True)
class RandomWalk(MotionModel):
    """Isotropic Brownian displacement plus a constant drift (km/day)."""

    name = "random_walk"
    has_velocity = False

    diffusion_km_per_day: float
    mean_current_km_per_day: tuple[float, float] = field(default=(0.0, 0.0))

    @classmethod
    def from_config(cls, cfg: MotionConfig) -> RandomWalk:
        return cls(cfg.diffusion_km_per_day, (cfg.mean_current_east_km_per_day, cfg.mean_current_north_km_per_day))

    def reversed(self) -> MotionModel:
        east, north = self.mean_current_km_per_day
        return dataclasses.replace(self, mean_current_km_per_day=(-east, -north))

    def transition(self, dt_days: float) -> LinearGaussian:
        sd = self.diffusion_km_per_day * np.sqrt(max(dt_days, 0.0))
        return LinearGaussian(
            A=np.eye(2), b=np.asarray(self.mean_current_km_per_day, dtype=float) * dt_days, L=sd * np.eye(2)
        )
