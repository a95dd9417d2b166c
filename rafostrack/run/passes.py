"""A pass is a value: a `PassSpec` goes in, a `PassResult` comes out.

The method (`run.method`) is a loop over passes: each tracks the float's record once with
one problem (its beacon table, float and model values), one seed, one particle count and
one way of smoothing. A spec says all of that; `one_pass.run_pass` tracks it and gives the
pass's estimate, evidence and seconds. The user's configuration is never rewritten: a
spec's problem carries it, and what the pass does otherwise is in the spec's own fields.

The method's three kinds of pass:
- `robust_pass`, the first: the TOA noise sd widened to `[calibrate]
  first_pass_toa_sigma_s` (unless the user set it), so that timing errors of a few seconds
  do not lose the float, and the float clock in the state (`motion.clock.ClockWalk`, a walk
  of `[calibrate] first_pass_clock_walk_s_per_sqrt_day`), so that a wrong or missing end
  clock offset does not move the track;
- `feeding_pass`, a pass whose track and labels feed calibration, tracked with the last
  calibration;
- `final_pass`, the configured pass with the last calibration: the float's result.
Passes that feed calibration track at most `[calibrate] max_particles` particles and are
always smoothed, by FFBSm alone on `CALIBRATION_COLUMNS` points (their labels and track
then use the whole record, whatever the output asks for).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from ..calibrate import Calibration
from ..calibrate.metadata_checks import MetadataCheck
from ..calibrate.source_scan import with_supported_schedule
from ..config import Config
from ..problem import FloatProblem, ModelValues
from ..smoothing.ffbsm import MAX_COLUMNS
from ..summaries.estimates import Estimate

NuisanceCov = Callable[[NDArray[np.datetime64]], NDArray[np.float64]]  # times -> (n, 2, 2) km^2

# FFBSm quantile points per step in the passes that feed calibration. Their track and labels
# are what calibration reads; on 512 points rather than the whole 1000-particle clouds their
# backward pass costs a quarter, and the sample's first-pass track moves by 0.08 km RMSE
# with the same labels (docs/decisions.md).
CALIBRATION_COLUMNS = 512


@dataclass(frozen=True)
class Smoothing:
    """How a pass smooths: not at all, by FFBSm on at most `ffbsm_columns` points of each
    step's cloud, or (`two_filter`) by joining a backward filter of at most
    `backward_particles` particles (0: the forward filter's) run from the end fix."""

    enabled: bool
    two_filter: bool = False
    backward_particles: int = 0
    ffbsm_columns: int = MAX_COLUMNS

    @classmethod
    def configured(cls, config: Config) -> Smoothing:
        """`[smoother]` as the user configured it."""
        smoother = config.smoother
        return cls(smoother.enabled, smoother.two_filter, smoother.backward_particles)


@dataclass(frozen=True)
class PassSpec:
    """One pass: the problem it tracks (`problem.model`: the model values in place of the
    configured ones), its `[filter]` seed and particles, how it smooths, the float clock's
    walk in the state (s/sqrt(day); 0: the clock as the problem has it), the position
    covariance to add that the model leaves out (`Calibration.nuisance_cov_at`), whether
    the filtered estimate is summarised too, and its name for progress ("pass 2 of 3")."""

    problem: FloatProblem
    seed: int
    particles: int
    smoothing: Smoothing
    clock_walk_s_per_sqrt_day: float = 0.0
    extra_cov: NuisanceCov | None = None
    also_filtered: bool = False
    name: str = "pass 1 of 1"

    @classmethod
    def configured(cls, problem: FloatProblem, *, also_filtered: bool = False, name: str = "pass 1 of 1") -> PassSpec:
        """The pass the user configured: `[filter]` seed and particles, `[smoother]`."""
        config = problem.config
        return cls(problem, config.filter.seed, config.filter.particles, Smoothing.configured(config),
                   also_filtered=also_filtered, name=name)  # fmt: skip

    def reseeded(self) -> PassSpec:
        """The same pass with the next seed: the same method, other random draws."""
        return dataclasses.replace(self, seed=self.seed + 1)

    def tracking_config(self) -> Config:
        """What the pass's components are built from: the problem's configuration with its
        model values (`FloatProblem.tracking_config`), this pass's seed and particles."""
        config = self.problem.tracking_config
        return dataclasses.replace(
            config, filter=dataclasses.replace(config.filter, seed=self.seed, particles=self.particles)
        )


@dataclass(frozen=True)
class Seconds:
    """Where a pass (or several) spent its time: filter, smoother, calibration."""

    filter_s: float = 0.0
    smoother_s: float = 0.0
    calibrate_s: float = 0.0

    def __add__(self, other: Seconds) -> Seconds:
        return Seconds(
            self.filter_s + other.filter_s, self.smoother_s + other.smoother_s, self.calibrate_s + other.calibrate_s
        )


@dataclass(frozen=True)
class FilterCounts:
    """What a pass's forward filter counted: resamplings, the ESS at each window, the windows
    the recovery monitor searched and those where it re-seeded part of the cloud."""

    n_resamples: int = 0
    filter_ess: tuple[float, ...] = ()
    n_checks: int = 0
    n_reseeds: int = 0


@dataclass(frozen=True)
class PassResult:
    """One pass's estimate (smoothed when the pass smooths, else filtered), the filtered one
    when asked for, what its filter counted and warned of, which smoother made the estimate
    ("ffbsm", "two_filter" or "none") and its seconds."""

    estimate: Estimate
    filtered: Estimate | None
    counts: FilterCounts
    warnings: tuple[str, ...]
    smoother: str
    seconds: Seconds

    @property
    def track(self) -> pd.DataFrame:
        return self.estimate.track

    @property
    def labels(self) -> pd.DataFrame:
        return self.estimate.labels

    @property
    def evidence(self) -> float:
        """log p(y_1..T) of the pass's filter: the sum of its windows' log p(y_t | y_1..t-1)."""
        return float(np.nansum(self.estimate.track["loglik"].to_numpy()))


def _feeding_smoothing() -> Smoothing:
    """How a pass that feeds calibration smooths: FFBSm alone, on `CALIBRATION_COLUMNS` points."""
    return Smoothing(enabled=True, two_filter=False, ffbsm_columns=CALIBRATION_COLUMNS)


def _feeding_particles(config: Config) -> int:
    """A pass that feeds calibration: at most `[calibrate] max_particles` particles."""
    return min(config.filter.particles, config.calibrate.max_particles)


def robust_pass(problem: FloatProblem, name: str) -> PassSpec:
    """The robust first pass (module docstring)."""
    config = problem.config
    sigma = config.model.toa_sigma_s
    if ("model", "toa_sigma_s") not in config.explicit:
        sigma = max(sigma, config.calibrate.first_pass_toa_sigma_s)
    robust = dataclasses.replace(problem, model=ModelValues(toa_sigma_s=sigma))
    walk = config.calibrate.first_pass_clock_walk_s_per_sqrt_day
    return PassSpec(robust, config.filter.seed, _feeding_particles(config), _feeding_smoothing(), walk, name=name)


def feeding_pass(
    problem: FloatProblem, calibration: Calibration, name: str = "", schedule: list[MetadataCheck] | None = None
) -> PassSpec:
    """A pass that feeds calibration, tracked with `calibration` (the beacon table with the
    schedule of `schedule`'s checks where given: a source scan's candidate)."""
    calibrated = calibration.calibrated(problem)
    if schedule:
        calibrated = dataclasses.replace(calibrated, beacons=with_supported_schedule(calibrated.beacons, schedule))
    config = problem.config
    return PassSpec(calibrated, config.filter.seed, _feeding_particles(config), _feeding_smoothing(),
                    extra_cov=calibration.nuisance_cov_at, name=name)  # fmt: skip


def final_pass(problem: FloatProblem, calibration: Calibration, also_filtered: bool, name: str) -> PassSpec:
    """The configured pass, tracked with `calibration`; the position variance the calibration
    leaves undetermined (`Calibration.nuisance_cov_km2`) added to its covariance."""
    configured = PassSpec.configured(calibration.calibrated(problem), also_filtered=also_filtered, name=name)
    return dataclasses.replace(configured, extra_cov=calibration.nuisance_cov_at)
