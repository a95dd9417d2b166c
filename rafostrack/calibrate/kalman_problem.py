"""The batch Kalman smoother's state-space problem (`calibrate.kalman`): its unknowns, priors
and hyperparameters.

The unknowns u: per node k (launch, windows with labelled arrivals, end fix) the position
offset from the nominal track (east, north km), the velocity (km/day), the clock residual
(s) and its rate (s/day), `NODE` of them; then the static parameters (mean current, shared
slowness deviation, per heard beacon offset, drift and slowness deviation). Every term of
the model (arrivals, motion between nodes, priors, the end fix) is a group of whitened
residual rows with their sparse Jacobian (`kalman_rows.Rows`), built at a linearisation
point u (`kalman_terms.linearise`) and reduced to normal-equation terms
(`kalman_rows.Normal`) for the solver and the evidence (`calibrate.kalman_evidence`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..model.geodesy import displace

# Unknowns per node: east, north (km), v_east, v_north (km/day), clock residual (s), its rate (s/day).
NODE = 6
VELOCITY, CLOCK, RATE = 2, 4, 5
LOG_2PI = float(np.log(2.0 * np.pi))


@dataclass(frozen=True)
class KalmanPriors:
    """Prior sds of the static parameters and of the clock where it was measured."""

    sound_speed_m_s: float = 20.0
    beacon_sound_speed_m_s: float = 2.0
    offset_s: float = 3.0
    drift_s_per_day: float = 0.01
    # A source whose offset or drift the metadata checks found contradicted by the arrivals
    # (`Problem.released`): its corrections are the data's, under these wide priors.
    released_offset_s: float = 300.0
    released_drift_s_per_day: float = 0.2
    source_position_km: float = 0.5  # per axis, where positions are unknowns (`Problem.source_positions`)
    released_position_km: float = 100.0
    clock_rate_s_per_day: float = 0.1  # of the clock residual's rate at launch
    mean_current_km_per_day: float = 20.0


@dataclass(frozen=True)
class Hyper:
    """The smoother's hyperparameters (fitted by maximum marginal likelihood)."""

    velocity_sd_km_per_day: float
    decorrelation_days: float
    toa_sigma_s: float
    clock_rate_sd_s_per_day: float  # q: the clock rate's random walk, s/day per sqrt(day)

    # Bounds of the search, per field (a shorter time scale than a day cannot be told from
    # position errors by daily windows).
    LOWER = (0.3, 0.5, 0.2, 1e-5)
    UPPER = (40.0, 60.0, 20.0, 0.3)
    # Weak log-normal priors (`log_hyperprior`): medians and sds of the natural logs.
    PRIOR_MEDIAN = (5.0, 5.0, 2.0, 0.01)
    PRIOR_LOG_SD = (1.5, 1.5, 1.0, 1.0)

    def vector(self) -> NDArray[np.float64]:
        return np.log(dataclasses.astuple(self))

    @classmethod
    def from_vector(cls, x: NDArray, lower: tuple[float, ...] = LOWER) -> Hyper:
        return cls(*np.clip(np.exp(x), lower, cls.UPPER).tolist())

    @classmethod
    def lower_with_clock_floor(cls, clock_rate_sd_s_per_day: float) -> tuple[float, ...]:
        """`LOWER` with the clock's q held at or above `clock_rate_sd_s_per_day`."""
        return (*cls.LOWER[:3], max(cls.LOWER[3], clock_rate_sd_s_per_day))


HYPER_FIELDS = tuple(f.name for f in dataclasses.fields(Hyper))


@dataclass(frozen=True)
class Problem:
    """What the smoother fits: the nodes (times, nominal positions, fixes) and the arrivals."""

    time: NDArray[np.datetime64]  # (K,) node times, ascending
    lat: NDArray[np.float64]  # (K,) nominal positions
    lon: NDArray[np.float64]
    launch_sd_km: float
    end_sd_km: float | None  # the last node is the end fix when given
    node: NDArray[np.intp]  # (J,) node of each arrival
    beacon: NDArray[np.intp]  # (J,) index among the heard beacons
    toa_s: NDArray[np.float64]
    delay_s: NDArray[np.float64]  # (J,) catalogue offset + drift + linear clock
    drift_days: NDArray[np.float64]  # (J,) days since the beacon's epoch, minus its mid-record value
    beacon_lat: NDArray[np.float64]  # (H,) heard beacons
    beacon_lon: NDArray[np.float64]
    slowness_s_per_m: float  # s0 = 1 / configured sound speed
    # The clock residual's prior sd where the clock was measured: at launch, and at the end
    # fix (None: the end offset was not measured, no row).
    clock_sd_s: tuple[float, float | None] = (0.5, 0.5)
    released: NDArray[np.bool_] | None = None  # (H,) sources under `KalmanPriors.released_*`
    # The heard sources' positions as unknowns too (east, north km from the table's, under
    # `KalmanPriors.source_position_km`, or `released_position_km` for the sources in
    # `released_positions`): for the metadata checks, and for a fit that moves a source.
    source_positions: bool = False
    released_positions: NDArray[np.bool_] | None = None  # (H,)

    @property
    def n_nodes(self) -> int:
        return len(self.time)

    @property
    def n_heard(self) -> int:
        return len(self.beacon_lat)

    @property
    def n_unknowns(self) -> int:
        return NODE * self.n_nodes + 3 + (5 if self.source_positions else 3) * self.n_heard

    # Static unknowns after the nodes: vbar (2), ds, then a_i, d_i, ds_i per heard beacon.
    @property
    def vbar(self) -> int:
        """Index of the mean current's east component (north follows)."""
        return NODE * self.n_nodes

    @property
    def ds(self) -> int:
        return NODE * self.n_nodes + 2

    def per_beacon(self, block: int) -> NDArray[np.intp]:
        """Indices of the per-beacon unknowns: block 0 = a_i, 1 = d_i, 2 = ds_i, and with
        `source_positions` 3 = the source's east, 4 = its north displacement (km)."""
        return NODE * self.n_nodes + 3 + block * self.n_heard + np.arange(self.n_heard)


def node_positions(problem: Problem, u: NDArray) -> tuple[NDArray, NDArray]:
    k = np.arange(problem.n_nodes)
    return displace(problem.lat, problem.lon, u[NODE * k], u[NODE * k + 1])


def timing_prior_sd(problem: Problem, priors: KalmanPriors) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(H,) each heard source's prior sd of its offset (s) and of its drift (s/day)."""
    released = np.zeros(problem.n_heard, dtype=bool) if problem.released is None else problem.released
    return (
        np.where(released, priors.released_offset_s, priors.offset_s),
        np.where(released, priors.released_drift_s_per_day, priors.drift_s_per_day),
    )


def position_prior_sd(problem: Problem, priors: KalmanPriors) -> NDArray[np.float64]:
    """(H,) the prior sd of each heard source's position, per axis (km)."""
    released = np.zeros(problem.n_heard, bool) if problem.released_positions is None else problem.released_positions
    return np.where(released, priors.released_position_km, priors.source_position_km)
