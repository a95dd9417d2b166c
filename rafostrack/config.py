"""Run configuration: defaults, layered TOML overrides and validation.

Layers, later wins: the package's `default.toml` (also at `configs/default.toml`), a
`rafostrack.toml` in the mission directory, `--config FILE`, command-line flags. Every
layer is checked against the defaults: an unknown section or key, a wrong type or a value
out of range is an `InputError` naming the file and key.
"""

from __future__ import annotations

import copy
import math
import re
import tomllib
from dataclasses import asdict, dataclass
from importlib import resources
from pathlib import Path
from typing import Any

from .errors import InputError, nearest

METHODS = ("exact", "bp", "unranked", "labeled")


@dataclass(frozen=True)
class ModelConfig:
    """Measurement model (paper section 2): arrival times, detection, clutter."""

    sound_speed_m_s: float
    toa_sigma_s: float
    p_detect: float
    clutter_rate: float
    multipath_fraction: float
    multipath_delay_s: float
    detection_range_km: float
    detection_falloff_km: float
    window_s: float
    max_signals: int


@dataclass(frozen=True)
class MotionConfig:
    """Random-walk drift model (paper eq. 1)."""

    diffusion_km_per_day: float


@dataclass(frozen=True)
class FixesConfig:
    """Launch and end position fixes as observations."""

    launch_sd_km: float
    end_sd_km: float
    use_end_fix: bool


@dataclass(frozen=True)
class SmootherConfig:
    enabled: bool


@dataclass(frozen=True)
class AmbiguityConfig:
    """When a posterior counts as two separate modes (see posterior.two_modes)."""

    min_mode_weight: float
    min_separation_km: float
    separation_factor: float


@dataclass(frozen=True)
class FilterConfig:
    """Particle filter: size, seed, association method, resampling threshold."""

    particles: int
    seed: int
    method: str
    resample_ess_fraction: float


@dataclass(frozen=True)
class BPConfig:
    """Loopy belief propagation stopping rule."""

    tolerance: float
    max_iterations: int


@dataclass(frozen=True)
class Config:
    model: ModelConfig
    motion: MotionConfig
    fixes: FixesConfig
    filter: FilterConfig
    smoother: SmootherConfig
    ambiguity: AmbiguityConfig
    bp: BPConfig

    def to_dict(self) -> dict[str, dict[str, Any]]:
        return asdict(self)


_SECTIONS = {
    "model": ModelConfig,
    "motion": MotionConfig,
    "fixes": FixesConfig,
    "filter": FilterConfig,
    "smoother": SmootherConfig,
    "ambiguity": AmbiguityConfig,
    "bp": BPConfig,
}

# (predicate, what is expected) per key; keys not listed only need the right type.
_RANGES: dict[tuple[str, str], tuple[Any, str]] = {
    ("model", "sound_speed_m_s"): (lambda v: v > 0, "> 0"),
    ("model", "toa_sigma_s"): (lambda v: v > 0, "> 0"),
    ("model", "p_detect"): (lambda v: 0 < v < 1, "strictly between 0 and 1"),
    ("model", "clutter_rate"): (lambda v: v > 0, "> 0 (use a small value for clean data)"),
    ("model", "multipath_fraction"): (lambda v: 0 <= v < 1, "in [0, 1)"),
    ("model", "multipath_delay_s"): (lambda v: v > 0, "> 0"),
    ("model", "detection_range_km"): (lambda v: v >= 0, ">= 0 (0 = no range limit)"),
    ("model", "detection_falloff_km"): (lambda v: v > 0, "> 0"),
    ("model", "window_s"): (lambda v: v > 0, "> 0"),
    ("model", "max_signals"): (lambda v: v >= 1, ">= 1"),
    ("motion", "diffusion_km_per_day"): (lambda v: v > 0, "> 0"),
    ("fixes", "launch_sd_km"): (lambda v: v > 0, "> 0"),
    ("fixes", "end_sd_km"): (lambda v: v > 0, "> 0"),
    ("ambiguity", "min_mode_weight"): (lambda v: 0 < v <= 0.5, "in (0, 0.5]"),
    ("ambiguity", "min_separation_km"): (lambda v: v >= 0, ">= 0"),
    ("ambiguity", "separation_factor"): (lambda v: v > 0, "> 0"),
    ("filter", "particles"): (lambda v: 2 <= v <= 10_000_000, "between 2 and 10000000"),
    ("filter", "seed"): (lambda v: v >= 0, ">= 0"),
    ("filter", "method"): (lambda v: v in METHODS, f"one of {', '.join(METHODS)}"),
    ("filter", "resample_ess_fraction"): (lambda v: 0 <= v <= 1, "in [0, 1]"),
    ("bp", "tolerance"): (lambda v: v > 0, "> 0"),
    ("bp", "max_iterations"): (lambda v: v >= 1, ">= 1"),
}


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


def _default_layer() -> dict[str, dict[str, Any]]:
    text = resources.files("rafostrack").joinpath("default.toml").read_text(encoding="utf-8")
    return tomllib.loads(text)


def _check_value(section: str, key: str, value: Any, expected: Any, source: str) -> Any:
    where = f"{source}: [{section}] {key}"
    if isinstance(expected, bool) or isinstance(value, bool):
        if not (isinstance(expected, bool) and isinstance(value, bool)):
            kind = "true or false" if isinstance(expected, bool) else f"a {type(expected).__name__}"
            raise InputError(f"{where}: expected {kind}, got {_short(value)}")
        return value
    if isinstance(expected, float):
        if not isinstance(value, int | float):
            raise InputError(f"{where}: expected a number, got {_short(value)}")
        value = float(value)
        if not math.isfinite(value):
            raise InputError(f"{where}: expected a finite number, got {_short(value)}")
    elif isinstance(expected, int):
        if isinstance(value, float) and value.is_integer():
            value = int(value)
        if not isinstance(value, int):
            raise InputError(f"{where}: expected a whole number, got {_short(value)}")
    elif isinstance(expected, str) and not isinstance(value, str):
        raise InputError(f"{where}: expected a string, got {_short(value)}")
    check = _RANGES.get((section, key))
    if check is not None and not check[0](value):
        raise InputError(f"{where}: must be {check[1]}, got {_short(value)}")
    return value


def merge_layer(base: dict[str, dict[str, Any]], layer: dict[str, Any], source: str) -> dict[str, dict[str, Any]]:
    """Return `base` updated by `layer`, rejecting unknown sections/keys and bad values."""
    merged = copy.deepcopy(base)
    for section, values in layer.items():
        if section not in base and not isinstance(values, dict):
            owners = [s for s in base if section in base[s]]
            hint = f"; expected it under [{owners[0]}]" if owners else "; expected [section] then key = value"
            raise InputError(f"{source}: key {section!r} is outside any [section]{hint}")
        if section not in base:
            hint = nearest(section, base) or f" (expected one of {', '.join(f'[{s}]' for s in base)})"
            raise InputError(f"{source}: unknown section [{section}]{hint}")
        if not isinstance(values, dict):
            raise InputError(f"{source}: [{section}]: expected a table of keys, got {_short(values)}")
        for key, value in values.items():
            if key not in base[section]:
                hint = nearest(key, base[section]) or f" (expected one of {', '.join(base[section])})"
                raise InputError(f"{source}: unknown key [{section}] {key}{hint}")
            merged[section][key] = _check_value(section, key, value, base[section][key], source)
    return merged


def load_config(
    files: list[Path] | tuple[Path, ...] = (),
    overrides: dict[str, dict[str, Any]] | None = None,
) -> Config:
    """Build the effective configuration: defaults, then each file, then `overrides`."""
    layers = _default_layer()
    for path in files:
        layers = merge_layer(layers, _read_toml(Path(path)), str(path))
    if overrides:
        layers = merge_layer(layers, overrides, "command line")
    return Config(**{name: cls(**layers[name]) for name, cls in _SECTIONS.items()})


def with_overrides(config: Config, **sections: dict[str, Any]) -> Config:
    """A copy of `config` with some keys replaced, validated like any other layer."""
    merged = merge_layer(config.to_dict(), sections, "override")
    return Config(**{name: cls(**merged[name]) for name, cls in _SECTIONS.items()})
