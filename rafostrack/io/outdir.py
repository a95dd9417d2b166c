"""The output directory check, made before any work."""

from __future__ import annotations

import os
from pathlib import Path

from ..errors import InputError


def check_output_dir(path: Path) -> None:
    """Fail before any work when `path` cannot be an output directory: it, or the nearest
    ancestor that exists, is not a directory, or that directory is not writable."""
    path = Path(path)
    probe = path
    while not probe.exists() and probe.parent != probe:
        probe = probe.parent
    if probe.exists() and not probe.is_dir():
        what = "is a file" if probe == path else f"cannot be created: {probe} is a file"
        what += ", not a directory"
        raise InputError(f"{path}: output directory {what}; expected --out to name a writable directory")
    if probe.is_dir() and not os.access(probe, os.W_OK | os.X_OK):
        raise InputError(
            f"{path}: output directory is not writable ({probe} denies write access); "
            "expected --out to name a writable directory"
        )
