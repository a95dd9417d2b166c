"""Run configuration: defaults, layered TOML overrides and validation.

Layers, later wins: the package's `default.toml` (also at `configs/default.toml`), a
`rafostrack.toml` in the mission directory, `--config FILE`, command-line flags. Every
layer is checked against the defaults: an unknown section or key, a wrong type or a value
out of range is an `InputError` naming the file and key.
"""

from __future__ import annotations

import copy
import math
import tomllib
from dataclasses import asdict, dataclass, fields
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
    """Random-walk drift model (paper eq. 1) and launch uncertainty."""

    diffusion_km_per_day: float
    launch_sd_km: float


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
    filter: FilterConfig
    bp: BPConfig

    def to_dict(self) -> dict[str, dict[str, Any]]:
        return asdict(self)


_SECTIONS = {"model": ModelConfig, "motion": MotionConfig, "filter": FilterConfig, "bp": BPConfig}

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
    ("motion", "launch_sd_km"): (lambda v: v > 0, "> 0"),
    ("filter", "particles"): (lambda v: v >= 2, ">= 2"),
    ("filter", "seed"): (lambda v: v >= 0, ">= 0"),
    ("filter", "method"): (lambda v: v in METHODS, f"one of {', '.join(METHODS)}"),
    ("filter", "resample_ess_fraction"): (lambda v: 0 <= v <= 1, "in [0, 1]"),
    ("bp", "tolerance"): (lambda v: v > 0, "> 0"),
    ("bp", "max_iterations"): (lambda v: v >= 1, ">= 1"),
}


def _read_toml(path: Path) -> dict[str, Any]:
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise InputError(f"{path}: config file not found") from None
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{path}: not valid TOML: {exc}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read config: {exc}") from None


def _default_layer() -> dict[str, dict[str, Any]]:
    text = resources.files("rafostrack").joinpath("default.toml").read_text(encoding="utf-8")
    return tomllib.loads(text)


def _check_value(section: str, key: str, value: Any, expected: Any, source: str) -> Any:
    where = f"{source}: [{section}] {key}"
    if isinstance(expected, bool) or isinstance(value, bool):
        raise InputError(f"{where}: expected a {type(expected).__name__}, got {value!r}")
    if isinstance(expected, float):
        if not isinstance(value, int | float):
            raise InputError(f"{where}: expected a number, got {value!r}")
        value = float(value)
        if not math.isfinite(value):
            raise InputError(f"{where}: expected a finite number, got {value!r}")
    elif isinstance(expected, int):
        if isinstance(value, float) and value.is_integer():
            value = int(value)
        if not isinstance(value, int):
            raise InputError(f"{where}: expected a whole number, got {value!r}")
    elif isinstance(expected, str) and not isinstance(value, str):
        raise InputError(f"{where}: expected a string, got {value!r}")
    check = _RANGES.get((section, key))
    if check is not None and not check[0](value):
        raise InputError(f"{where}: must be {check[1]}, got {value!r}")
    return value


def merge_layer(base: dict[str, dict[str, Any]], layer: dict[str, Any], source: str) -> dict[str, dict[str, Any]]:
    """Return `base` updated by `layer`, rejecting unknown sections/keys and bad values."""
    merged = copy.deepcopy(base)
    for section, values in layer.items():
        if section not in base:
            raise InputError(f"{source}: unknown section [{section}]{nearest(section, base)}")
        if not isinstance(values, dict):
            raise InputError(f"{source}: [{section}] must be a table of keys")
        for key, value in values.items():
            if key not in base[section]:
                raise InputError(f"{source}: unknown key [{section}] {key}{nearest(key, base[section])}")
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


def section_fields(section: str) -> list[str]:
    return [f.name for f in fields(_SECTIONS[section])]
