"""Likelihood components: the evidence each kind of observation gives about a particle.

`ARRIVAL_LIKELIHOODS` maps the config's `[filter] likelihood` (ranked, unranked, labeled)
to a factory `(beacons, info, config) -> ArrivalLikelihood`; position fixes have
`PositionFixLikelihood`.
"""

from __future__ import annotations

from ..config import Config
from ..domain import BeaconTable, FloatInfo
from .arrivals import ARRIVAL_LIKELIHOODS, ArrivalLikelihood, LabelledArrivals, RankedArrivals
from .base import Evidence, Likelihood, MoveFactor, outlier_scale
from .fixes import PositionFixLikelihood, fix_loglik


def arrivals_from_config(beacons: BeaconTable, info: FloatInfo, config: Config) -> ArrivalLikelihood:
    """The configured arrival-time evidence model."""
    return ARRIVAL_LIKELIHOODS[config.filter.likelihood](beacons, info, config)


__all__ = [
    "ARRIVAL_LIKELIHOODS",
    "ArrivalLikelihood",
    "Evidence",
    "LabelledArrivals",
    "Likelihood",
    "MoveFactor",
    "PositionFixLikelihood",
    "RankedArrivals",
    "arrivals_from_config",
    "fix_loglik",
    "outlier_scale",
]
