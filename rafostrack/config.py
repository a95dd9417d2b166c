"""Run configuration: one typed field per key, its constraint declared beside it.

Values come only from the package's `default.toml` (every key, with a comment), then the
layers that override it, later wins: a `rafostrack.toml` in the mission directory,
`--config FILE`, command-line flags. Every layer is checked field by field: an unknown
section or key (with the nearest valid name suggested), a wrong type, or a value outside
the field's declared range is an `InputError` naming the file and key. A key that was
renamed gets a one-line error saying what to write instead.

The sections and their fields are in `rafostrack.config_sections`, importable from here too.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import re
import tomllib
from collections.abc import Callable
from importlib import resources
from pathlib import Path
from typing import Any, get_type_hints

from .config_sections import (
    SECTIONS,
    ABCConfig,
    AmbiguityConfig,
    BPConfig,
    CalibrateConfig,
    ChecksConfig,
    Config,
    ContextConfig,
    FilterConfig,
    FixesConfig,
    LegsConfig,
    ModelConfig,
    MotionConfig,
    QualityConfig,
    RecoveryConfig,
    SmootherConfig,
)
from .errors import InputError, nearest

# The sections (`config_sections`) and the functions that build a Config: what callers import.
__all__ = [
    "METHODS",
    "RENAMED",
    "SECTIONS",
    "ABCConfig",
    "AmbiguityConfig",
    "BPConfig",
    "CalibrateConfig",
    "ChecksConfig",
    "Config",
    "ContextConfig",
    "FilterConfig",
    "FixesConfig",
    "LegsConfig",
    "ModelConfig",
    "MotionConfig",
    "QualityConfig",
    "RecoveryConfig",
    "SmootherConfig",
    "check_value",
    "default_layer",
    "explicit_keys",
    "field_type",
    "key_comment",
    "load_config",
    "merge_layer",
    "method_overrides",
    "with_overrides",
]


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


def _got(value: Any, kind: type) -> str:
    """What a value of the wrong type is, for a message: a quoted TOML string that would be
    right without its quotes (`p_detect = "0.9"`) is named as such."""
    if isinstance(value, str) and _reads_as(value.strip(), kind):
        return f'the string "{value.strip()}" (remove the quotes)'
    return _short(value)


def _reads_as(text: str, kind: type) -> bool:
    """Whether `text`, unquoted, is a value of `kind` (bool, int or float)."""
    if kind is bool:
        return text in ("true", "false")
    try:
        (float if kind is float else int)(text)
    except ValueError:
        return False
    return True


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
            raise InputError(f"{where}: expected {expected}, got {_got(value, kind)}")
        return value
    if kind is float:
        if not isinstance(value, int | float):
            raise InputError(f"{where}: expected a number, got {_got(value, float)}")
        value = float(value)
        if not math.isfinite(value):
            raise InputError(f"{where}: expected a finite number, got {_short(value)}")
    elif kind is int:
        if isinstance(value, float) and value.is_integer():
            value = int(value)
        if not isinstance(value, int):
            raise InputError(f"{where}: expected a whole number, got {_got(value, int)}")
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
