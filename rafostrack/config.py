"""Run configuration: one typed field per key, its constraint declared beside it.

Values come only from the package's `default.toml` (every key, with a comment), then the
layers that override it, later wins: a `rafostrack.toml` in the mission directory,
`--config FILE`, command-line flags. Every layer is checked field by field: an unknown
section or key (with the nearest valid name suggested), a wrong type, or a value outside
the field's declared range is an `InputError` naming the file and key. A key that was
renamed gets a one-line error saying what to write instead.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import re
import tomllib
from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any, get_type_hints

from .errors import InputError, nearest


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


def _registry(module: str, name: str) -> Callable[[], Iterable[str]]:
    """Choices read from a registry `module.name` (a mapping or list of names) when checked."""

    def names() -> Iterable[str]:
        import importlib

        return list(getattr(importlib.import_module(module), name))

    return names


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

    model: str = setting(choices=_registry("rafostrack.motion", "MOTION_MODELS"))
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
    z_score: float = setting("> 0", _positive)
    launch_z_score: float = setting("> 0", _positive)
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
    likelihood: str = setting(choices=_registry("rafostrack.likelihoods", "ARRIVAL_LIKELIHOODS"))
    engine: str = setting(choices=_registry("rafostrack.engines", "ENGINES"))
    resampling: str = setting(choices=_registry("rafostrack.filtering.resampling", "RESAMPLERS"))
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

# The paper's methods, each a (likelihood, engine) pair; they were the values of the
# removed `[filter] method` key and name the compared methods in experiments and benchmarks.
METHODS: dict[str, tuple[str, str]] = {
    "exact": ("ranked", "exact"),
    "bp": ("ranked", "bp"),
    "unranked": ("unranked", "exact"),
    "labeled": ("labeled", "exact"),
}


def method_overrides(method: str) -> dict[str, str]:
    """The `[filter]` keys of one of the paper's methods (`METHODS`)."""
    likelihood, engine = METHODS[method]
    return {"likelihood": likelihood, "engine": engine}


def _method_hint(value: Any) -> str:
    likelihood, engine = METHODS.get(str(value), METHODS["exact"])
    return (
        f"was split into two keys: write likelihood = {likelihood!r} and engine = {engine!r} "
        "(likelihood: ranked, unranked or labeled; engine: how the association sum is computed)"
    )


# Keys that no longer exist: (section, key) -> what to write instead, given the old value.
RENAMED: dict[tuple[str, str], Callable[[Any], str]] = {("filter", "method"): _method_hint}

_MAX_CONFIG_BYTES = 1 << 20  # a config file is a few KB; refuse absurd ones before parsing
_DEEP_KEY = re.compile(r"(?:[^.\n=\[\]]{0,64}\.){64}")  # a key dotted 64 levels deep


def _short(value: Any, limit: int = 60) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _read_toml(path: Path) -> dict[str, Any]:
    try:
        with open(path, "rb") as fh:
            data = fh.read(_MAX_CONFIG_BYTES + 1)
    except FileNotFoundError:
        raise InputError(f"{path}: config file not found (expected a TOML file)") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read config: {exc.strerror or exc}") from None
    if len(data) > _MAX_CONFIG_BYTES:
        raise InputError(f"{path}: config file larger than {_MAX_CONFIG_BYTES} bytes; expected a small TOML file")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise InputError(f"{path}: line {line}: not UTF-8 text; expected a UTF-8 TOML file") from None
    if _DEEP_KEY.search(text):
        raise InputError(f"{path}: keys nested 64 or more levels deep; expected [section] key = value")
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{path}: not valid TOML: {exc}") from None
    except RecursionError:
        raise InputError(f"{path}: not valid TOML: values nested too deeply") from None


def default_layer() -> dict[str, dict[str, Any]]:
    """The packaged default.toml, as nested dicts."""
    text = resources.files("rafostrack").joinpath("default.toml").read_text(encoding="utf-8")
    return tomllib.loads(text)


def _field(section: str, key: str) -> tuple[dataclasses.Field, type]:
    cls = SECTIONS[section]
    return {f.name: f for f in dataclasses.fields(cls)}[key], get_type_hints(cls)[key]


def field_type(section: str, key: str) -> type:
    """The Python type of [section] key (float, int, bool or str)."""
    return _field(section, key)[1]


def key_comment(section: str, key: str) -> str:
    """The comment above [section] key in default.toml, as one line (for help texts); keys
    on consecutive lines share the comment above the first of them."""
    text = resources.files("rafostrack").joinpath("default.toml").read_text(encoding="utf-8")
    current: str | None = None
    comment: list[str] = []
    after_key = False
    for line in text.splitlines():
        stripped = line.strip()
        if stripped.startswith("[") and stripped.endswith("]"):
            current, comment, after_key = stripped[1:-1], [], False
        elif stripped.startswith("#"):
            comment = [*([] if after_key else comment), stripped.lstrip("# ")]
            after_key = False
        elif "=" in stripped:
            if current == section and stripped.split("=")[0].strip() == key:
                return " ".join(comment)
            after_key = True
        elif not stripped:
            comment, after_key = [], False
    return ""


def check_value(section: str, key: str, value: Any, source: str) -> Any:
    """`value` for [section] key, converted to the field's type and checked against its
    declared constraint; an `InputError` naming `source` and the key otherwise."""
    where = f"{source}: [{section}] {key}"
    spec, kind = _field(section, key)
    if kind is bool or isinstance(value, bool):
        if not (kind is bool and isinstance(value, bool)):
            expected = "true or false" if kind is bool else f"a {kind.__name__}"
            raise InputError(f"{where}: expected {expected}, got {_short(value)}")
        return value
    if kind is float:
        if not isinstance(value, int | float):
            raise InputError(f"{where}: expected a number, got {_short(value)}")
        value = float(value)
        if not math.isfinite(value):
            raise InputError(f"{where}: expected a finite number, got {_short(value)}")
    elif kind is int:
        if isinstance(value, float) and value.is_integer():
            value = int(value)
        if not isinstance(value, int):
            raise InputError(f"{where}: expected a whole number, got {_short(value)}")
    elif kind is str and not isinstance(value, str):
        raise InputError(f"{where}: expected a string, got {_short(value)}")
    meta = spec.metadata
    if meta.get("choices") is not None:
        names = list(meta["choices"]())
        if value not in names:
            raise InputError(f"{where}: must be one of {', '.join(names)}, got {_short(value)}{nearest(value, names)}")
    if meta.get("check") is not None and not meta["check"](value):
        raise InputError(f"{where}: must be {meta['expect']}, got {_short(value)}")
    return value


def merge_layer(base: dict[str, dict[str, Any]], layer: dict[str, Any], source: str) -> dict[str, dict[str, Any]]:
    """Return `base` updated by `layer`, rejecting unknown sections/keys and bad values."""
    merged = copy.deepcopy(base)
    for section, values in layer.items():
        if section not in SECTIONS and not isinstance(values, dict):
            owners = [s for s in SECTIONS if section in base.get(s, {})]
            hint = f"; expected it under [{owners[0]}]" if owners else "; expected [section] then key = value"
            raise InputError(f"{source}: key {section!r} is outside any [section]{hint}")
        if section not in SECTIONS:
            hint = nearest(section, SECTIONS) or f" (expected one of {', '.join(f'[{s}]' for s in SECTIONS)})"
            raise InputError(f"{source}: unknown section [{section}]{hint}")
        if not isinstance(values, dict):
            raise InputError(f"{source}: [{section}]: expected a table of keys, got {_short(values)}")
        known = [f.name for f in dataclasses.fields(SECTIONS[section])]
        for key, value in values.items():
            if (section, key) in RENAMED:
                raise InputError(f"{source}: [{section}] {key} {RENAMED[section, key](value)}")
            if key not in known:
                hint = nearest(key, known) or f" (expected one of {', '.join(known)})"
                raise InputError(f"{source}: unknown key [{section}] {key}{hint}")
            merged.setdefault(section, {})[key] = check_value(section, key, value, source)
    return merged


def _build(layers: dict[str, dict[str, Any]], explicit: frozenset[tuple[str, str]] = frozenset()) -> Config:
    return Config(**{name: cls(**layers[name]) for name, cls in SECTIONS.items()}, explicit=explicit)


def load_config(
    files: list[Path] | tuple[Path, ...] = (),
    overrides: dict[str, dict[str, Any]] | None = None,
) -> Config:
    """Build the effective configuration: defaults, then each file, then `overrides`; its
    `explicit` keys are those the files and `overrides` set (`explicit_keys`)."""
    layers = merge_layer({}, default_layer(), "default.toml")
    for path in files:
        layers = merge_layer(layers, _read_toml(Path(path)), str(path))
    if overrides:
        layers = merge_layer(layers, overrides, "command line")
    return _build(layers, frozenset(explicit_keys(files, overrides)))


def explicit_keys(
    files: list[Path] | tuple[Path, ...] = (), overrides: dict[str, dict[str, Any]] | None = None
) -> set[tuple[str, str]]:
    """The (section, key) pairs that a config file or the command line sets (not the defaults)."""
    keys: set[tuple[str, str]] = set()
    for layer in [*(_read_toml(Path(path)) for path in files), overrides or {}]:
        keys |= {(s, k) for s, values in layer.items() if isinstance(values, dict) for k in values}
    return keys


def with_overrides(config: Config, **sections: dict[str, Any]) -> Config:
    """A copy of `config` with some keys replaced, validated like any other layer; the keys
    the user set stay `config.explicit` (a program's override is not the user's)."""
    return _build(merge_layer(config.to_dict(), sections, "override"), config.explicit)
