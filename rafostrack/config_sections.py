"""The configuration's sections: one frozen dataclass per `[section]` of default.toml, one
typed field per key with its constraint declared beside it (`setting`), and `Config`, the
sections together.

Defaults live in default.toml only; `rafostrack.config` builds a `Config` from it and the
layers over it, checking each value against its field.
"""

from __future__ import annotations

import dataclasses
import importlib
from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass, field
from typing import Any, get_type_hints


def setting(
    expect: str | None = None,
    check: Callable[[Any], bool] | None = None,
    *,
    choices: Callable[[], Iterable[str]] | None = None,
) -> Any:
    """A config field whose value must satisfy `check` (described by `expect`, e.g. "> 0"),
    or be one of `choices()` (a callable, so that a registry is consulted when a value is
    checked, not when this module is imported). Defaults live in default.toml only."""
    return field(metadata={"expect": expect, "check": check, "choices": choices})


def _positive(v: float) -> bool:
    return v > 0


def _non_negative(v: float) -> bool:
    return v >= 0


def _probability_open(v: float) -> bool:
    return 0 < v < 1


def _fraction(v: float) -> bool:
    return 0 <= v <= 1


@dataclass(frozen=True)
class RegistryChoices:
    """The names in a registry `module.name` (a mapping or list of names), read when a value
    is checked. The registries live in the stages above the configuration, which it may not
    import: tests/test_architecture.py checks that each one resolves, in a stage allowed."""

    module: str
    name: str

    def __call__(self) -> Iterable[str]:
        return list(getattr(importlib.import_module(self.module), self.name))


@dataclass(frozen=True)
class ModelConfig:
    """Measurement model (paper section 2): arrival times, detection, clutter."""

    sound_speed_m_s: float = setting("> 0", _positive)
    toa_sigma_s: float = setting("> 0", _positive)
    p_detect: float = setting("strictly between 0 and 1", _probability_open)
    clutter_rate: float = setting("> 0 (use a small value for clean data)", _positive)
    multipath_fraction: float = setting("in [0, 1)", lambda v: 0 <= v < 1)
    multipath_delay_s: float = setting("> 0", _positive)
    multipath_delay_shape: int = setting("1 or 2", lambda v: v in (1, 2))
    echo_fraction: float = setting("in [0, 1)", lambda v: 0 <= v < 1)
    detection_range_km: float = setting(">= 0 (0 = no range limit)", _non_negative)
    detection_falloff_km: float = setting("> 0", _positive)
    window_s: float = setting("> 0", _positive)
    max_signals: int = setting(">= 1", lambda v: v >= 1)


@dataclass(frozen=True)
class MotionConfig:
    """How the float drifts between windows (`rafostrack.motion`)."""

    model: str = setting(choices=RegistryChoices("rafostrack.motion", "MOTION_MODELS"))
    diffusion_km_per_day: float = setting("> 0", _positive)
    velocity_sd_km_per_day: float = setting("> 0", _positive)
    decorrelation_days: float = setting("> 0", _positive)
    mean_current_east_km_per_day: float = setting()
    mean_current_north_km_per_day: float = setting()


@dataclass(frozen=True)
class RecoveryConfig:
    """Robust drift and lost-track recovery (`rafostrack.filtering.recovery`)."""

    enabled: bool = setting()
    jump_rate_per_day: float = setting(">= 0", _non_negative)
    jump_sd_km: float = setting("> 0", _positive)
    search_radius_km: float = setting("> 0", _positive)
    reseed_fraction: float = setting("in (0, 0.9]", lambda v: 0 < v <= 0.9)
    check_every: int = setting(">= 1", lambda v: v >= 1)


@dataclass(frozen=True)
class CalibrateConfig:
    """Estimate the record's nuisances from a first pass (`rafostrack.calibrate`)."""

    enabled: bool = setting()
    first_pass_toa_sigma_s: float = setting("> 0", _positive)
    first_pass_clock_walk_s_per_sqrt_day: float = setting(">= 0", lambda v: v >= 0)
    iterations: int = setting("between 1 and 5", lambda v: 1 <= v <= 5)
    max_particles: int = setting("between 2 and 10000000", lambda v: 2 <= v <= 10_000_000)
    min_clock_rate_sd_s_per_day: float = setting(
        "between 0 and 0.3 (the search's upper bound)", lambda v: 0 <= v <= 0.3
    )


@dataclass(frozen=True)
class FixesConfig:
    """Launch and end position fixes as observations."""

    launch_sd_km: float = setting("> 0", _positive)
    end_sd_km: float = setting("> 0", _positive)
    use_end_fix: bool = setting()
    clock_offset_sd_s: float = setting("> 0", _positive)


@dataclass(frozen=True)
class ChecksConfig:
    """The table values checked against the arrivals (`rafostrack.calibrate.metadata_checks`)."""

    enabled: bool = setting()
    source_scan: bool = setting()
    release_sources: bool = setting()
    z_score: float = setting("> 0", _positive)
    launch_z_score: float = setting("> 0", _positive)
    mission_z_score: float = setting("> 0", _positive)
    fix_tolerance_km: float = setting("> 0", _positive)
    position_tolerance_km: float = setting("> 0", _positive)
    clock_tolerance_s: float = setting("> 0", _positive)
    offset_tolerance_s: float = setting("> 0", _positive)
    drift_tolerance_s_per_day: float = setting("> 0", _positive)


@dataclass(frozen=True)
class SmootherConfig:
    enabled: bool = setting()
    two_filter: bool = setting()
    backward_particles: int = setting("0 or >= 2", lambda v: v == 0 or v >= 2)


@dataclass(frozen=True)
class AmbiguityConfig:
    """When a posterior counts as two separate modes (see posterior.two_modes)."""

    min_mode_weight: float = setting("in (0, 0.5]", lambda v: 0 < v <= 0.5)
    min_separation_km: float = setting(">= 0", _non_negative)
    separation_factor: float = setting("> 0", _positive)


@dataclass(frozen=True)
class FilterConfig:
    """Particle filter: size, seed, the evidence model and its engine, resampling."""

    particles: int = setting("between 2 and 10000000", lambda v: 2 <= v <= 10_000_000)
    seed: int = setting(">= 0", _non_negative)
    likelihood: str = setting(choices=RegistryChoices("rafostrack.likelihoods", "ARRIVAL_LIKELIHOODS"))
    engine: str = setting(choices=RegistryChoices("rafostrack.engines", "ENGINES"))
    resampling: str = setting(choices=RegistryChoices("rafostrack.filtering.resampling", "RESAMPLERS"))
    resample_ess_fraction: float = setting("in [0, 1]", _fraction)
    guided_fraction: float = setting("in [0, 1)", lambda v: 0 <= v < 1)
    mode_link_km: float = setting("> 0", _positive)
    max_modes: int = setting(">= 1", lambda v: v >= 1)
    min_mode_mass: float = setting("in [0, 1)", lambda v: 0 <= v < 1)


@dataclass(frozen=True)
class BPConfig:
    """Loopy belief propagation stopping rule."""

    tolerance: float = setting("> 0", _positive)
    max_iterations: int = setting(">= 1", lambda v: v >= 1)


@dataclass(frozen=True)
class QualityConfig:
    """Correlation height (the arrival file's `quality`) as evidence of source vs clutter
    (`rafostrack.likelihoods.quality`): Gaussian class-conditional densities of the height."""

    enabled: bool = setting()
    source_mean: float = setting()
    source_sd: float = setting("> 0", _positive)
    clutter_mean: float = setting()
    clutter_sd: float = setting("> 0", _positive)
    max_abs_log_ratio: float = setting("> 0", _positive)


@dataclass(frozen=True)
class ContextConfig:
    """Context constraints on the float's moves (`rafostrack.context`): land, the sea floor."""

    land: bool = setting()
    bathymetry: str = setting()
    rule: str = setting(choices=lambda: ("entry", "naive"))
    float_depth_m: float = setting("in [0, 11000] (0 = not set)", lambda v: 0 <= v <= 11000)
    float_depth_sd_m: float = setting("> 0", _positive)
    depth_sign: str = setting(choices=lambda: ("auto", "up", "down"))
    depth_sd_m: float = setting("> 0", _positive)
    depth_sd_fraction: float = setting("in [0, 1]", _fraction)
    depth_horizontal_km: float = setting(">= 0", _non_negative)
    land_mask_error: float = setting("strictly between 0 and 0.5", lambda v: 0 < v < 0.5)
    cell_arcmin: float = setting("in [0.1, 60]", lambda v: 0.1 <= v <= 60)
    margin_deg: float = setting("in [0, 30]", lambda v: 0 <= v <= 30)


@dataclass(frozen=True)
class ABCConfig:
    """Approximate Bayesian computation engine (`engine = "abc"`, `rafostrack.engines.abc`)."""

    tolerance_s: float = setting("> 0", _positive)
    simulations: int = setting("between 1 and 100000", lambda v: 1 <= v <= 100_000)
    gap_s: float = setting(">= 0 (0 = no unmatched signals allowed)", _non_negative)
    stream: int = setting(">= 0", _non_negative)


@dataclass(frozen=True)
class LegsConfig:
    """`rafostrack legs`: the leg model's prior, the sampler and the likelihood grids (`rafostrack.legs`)."""

    iterations: int = setting(">= 100", lambda v: v >= 100)
    duration_min_days: float = setting("> 0", _positive)
    duration_max_days: float = setting("> 0", _positive)
    speed_mean_km_per_day: float = setting(">= 0", _non_negative)
    speed_sd_km_per_day: float = setting("> 0", _positive)
    heading_change_sd_deg: float = setting("> 0", _positive)
    wiggle_max_km: float = setting(">= 0", _non_negative)
    grid_spacing_km: float = setting("> 0", _positive)
    grid_half_width_km: float = setting("> 0", _positive)


@dataclass(frozen=True)
class Config:
    """The effective configuration: one dataclass per section, and which keys the user set.

    `explicit` holds the (section, key) pairs a config file or the command line sets (not
    the defaults, whatever their values): calibration keeps those as set. It is not a
    section: `to_dict()` (run.json, Parquet metadata) leaves it out."""

    model: ModelConfig
    motion: MotionConfig
    recovery: RecoveryConfig
    calibrate: CalibrateConfig
    fixes: FixesConfig
    checks: ChecksConfig
    filter: FilterConfig
    smoother: SmootherConfig
    ambiguity: AmbiguityConfig
    bp: BPConfig
    quality: QualityConfig
    context: ContextConfig
    abc: ABCConfig
    legs: LegsConfig
    explicit: frozenset[tuple[str, str]] = frozenset()  # keys the user set: not estimated

    def to_dict(self) -> dict[str, dict[str, Any]]:
        """Every section's values by key (not `explicit`)."""
        return {name: asdict(getattr(self, name)) for name in SECTIONS}


SECTIONS: dict[str, type] = {
    f.name: get_type_hints(Config)[f.name] for f in dataclasses.fields(Config) if f.name != "explicit"
}
