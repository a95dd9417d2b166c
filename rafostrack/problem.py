"""One float's problem: what a pass of the tracker needs besides the arrival record.

The beacon table, the float's description and the configuration always travel together:
the tracker (`run.one_pass.Tracker.from_problem`), the method (`run.method.track_record`)
and calibration (`calibrate.calibrate`) each take one `FloatProblem`. The keys the user
set travel inside the configuration (`Config.explicit`), so whatever holds the problem
knows which values calibration must leave alone. A calibration gives the calibrated
problem (`calibrate.Calibration.calibrated`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from .config import Config
from .domain import BeaconTable, FloatInfo


@dataclass(frozen=True)
class FloatProblem:
    """One float's beacons, description and configuration (with the keys the user set)."""

    beacons: BeaconTable
    info: FloatInfo
    config: Config

    def with_config(self, config: Config) -> FloatProblem:
        """The same float and beacons under `config`."""
        return dataclasses.replace(self, config=config)
