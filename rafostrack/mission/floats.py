"""One tracked float as the mission's array fit sees it: its confident labels as the batch
Kalman smoother's arrivals (`calibrate.timing_problem`), every heard source's position an
unknown, and the float's own hyperparameters.

The float's unknowns in the smoother's order are its nodes (east, north, velocity, clock,
rate), its mean current, then the array's: the shared slowness deviation and, per heard
source, its offset, drift, slowness deviation and position (`kalman_problem.Problem`). The
first two groups are the float's own; the last is a view of the mission's array vector
(`ArrayLayout.float_columns`). A source's drift is referred to one reference time for the
whole mission (`ArrayLayout.mid_days`), so that its offset means the same on every float.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..calibrate import INITIAL_CLOCK_RATE_SD_S_PER_DAY, kalman
from ..calibrate.kalman_problem import NODE
from ..calibrate.timing_problem import timing_problem
from ..config import Config
from ..domain import BeaconTable, FloatInfo
from ..summaries.estimates import Estimate

OWN_STATICS = 2  # the float's mean current (east, north km/day)
BANDWIDTH = 2 * NODE - 1  # the nodes' band half-width (`kalman_evidence.factorise`)


@dataclass(frozen=True)
class MissionFloat:
    """A float's smoother problem (positions of its heard sources as unknowns) and its
    hyperparameters; `days` (J,): each arrival's days since its source's epoch."""

    float_id: str
    problem: kalman.Problem
    heard: NDArray[np.intp]  # (H_f,) beacon-table rows of the heard sources
    days: NDArray[np.float64]
    hyper: kalman.Hyper
    # beacon-table rows of heard sources whose arrivals the fit sets aside (their weight 0):
    # the float is an outlier among those hearing the source (`array_fit.outlying_pairs`)
    set_aside: tuple[int, ...] = ()

    @property
    def kept(self) -> NDArray[np.float64]:
        """(J,) 1 for each arrival the fit weighs, 0 for those of a source set aside."""
        return (~np.isin(self.heard[self.problem.beacon], self.set_aside)).astype(float)

    @property
    def n_own(self) -> int:
        """The float's own unknowns: its nodes and its mean current."""
        return NODE * self.problem.n_nodes + OWN_STATICS

    @property
    def n_arrivals(self) -> int:
        return len(self.problem.toa_s)


def mission_float(
    float_id: str,
    estimate: Estimate,
    beacons: BeaconTable,
    info: FloatInfo,
    config: Config,
    hyper: kalman.Hyper | None = None,
) -> MissionFloat | None:
    """The float's problem from its track and confident labels, with the tables as given
    (the fit's corrections are to them), under `hyper` (its calibration's; else the
    configured values); None when it has too few confident arrivals."""
    built = timing_problem(estimate, beacons, info, config)
    if built is None:
        return None
    problem, heard, mid = built
    if hyper is None:
        model, motion = config.model, config.motion
        hyper = kalman.Hyper(
            motion.velocity_sd_km_per_day, motion.decorrelation_days, model.toa_sigma_s, INITIAL_CLOCK_RATE_SD_S_PER_DAY
        )
    days = problem.drift_days + mid[problem.beacon]
    return MissionFloat(float_id, dataclasses.replace(problem, source_positions=True), heard, days, hyper)


def referred(floats: list[MissionFloat], sources: NDArray[np.intp], mid_days: NDArray) -> list[MissionFloat]:
    """The floats with each arrival's drift time from its source's mission reference
    (`mid_days`, one per source of `sources`, the array's table rows)."""
    position = {int(row): g for g, row in enumerate(sources)}
    out = []
    for f in floats:
        ref = np.array([mid_days[position[int(row)]] for row in f.heard])
        out.append(
            dataclasses.replace(f, problem=dataclasses.replace(f.problem, drift_days=f.days - ref[f.problem.beacon]))
        )
    return out
