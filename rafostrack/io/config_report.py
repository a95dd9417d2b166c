"""`rafostrack config [MISSION]`: the effective configuration, each key with the layer it came from.

Layers as for `track` (docs/user-guide.md, "Configuration"): the package defaults, the mission's
`rafostrack.toml`, `--config FILE`, then command-line flags. The text is valid TOML (the
sources are comments), so it can be saved and used as a `--config` file.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from ..config import Config, _build, _read_toml, default_layer, merge_layer

DEFAULTS = "default"
COMMAND_LINE = "command line"


def toml_value(v: Any) -> str:
    """`v` written as a TOML value (bool, integer, float, string)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int | np.integer):
        return str(int(v))
    if isinstance(v, float | np.floating):
        return repr(float(v))
    if isinstance(v, str):
        return json.dumps(v)
    raise ValueError(f"cannot write {v!r} to TOML")


def layered_config(
    files: tuple[Path, ...] | list[Path], overrides: dict[str, dict[str, Any]] | None = None
) -> tuple[Config, dict[tuple[str, str], str]]:
    """The effective configuration (checked as `load_config` checks it) and, per (section,
    key), the last layer that set it: "default", a file's path, or "command line"."""
    layers = merge_layer({}, default_layer(), "default.toml")
    sources = {(s, k): DEFAULTS for s, values in layers.items() for k in values}
    named: list[tuple[str, dict[str, Any]]] = [(str(p), _read_toml(Path(p))) for p in files]
    if overrides:
        named.append((COMMAND_LINE, overrides))
    for source, layer in named:
        layers = merge_layer(layers, layer, source)
        sources.update({(s, k): source for s, values in layer.items() if isinstance(values, dict) for k in values})
    return _build(layers), sources


def render(config: Config, sources: dict[tuple[str, str], str], layer_names: list[str]) -> str:
    """TOML text of `config`, each key followed by a comment naming its source."""
    lines = ["# rafostrack: effective configuration; layers, later wins: " + " < ".join(layer_names)]
    for section, values in config.to_dict().items():
        lines += ["", f"[{section}]"]
        width = max(len(f"{k} = {toml_value(v)}") for k, v in values.items())
        for key, value in values.items():
            text = f"{key} = {toml_value(value)}"
            lines.append(f"{text:<{width}}  # {sources[section, key]}")
    return "\n".join(lines) + "\n"
