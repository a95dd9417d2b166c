"""The output directory check, made before any work."""

from __future__ import annotations

import os
import re
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


# A staging or trash sibling of an output directory <name> (`staging_dir`, `swap_into_place`).
SIBLING = re.compile(r"^\.(?P<name>.+)\.(?:tmp|trash)-(?P<pid>\d+)$")


def staging_dir(final: Path) -> Path:
    """A hidden sibling of `final` to build a new `final` in (`swap_into_place` installs it)."""
    final = Path(final)
    return final.parent / f".{final.name}.tmp-{os.getpid()}"


def _alive(pid: int) -> bool:
    """Whether process `pid` runs (or exists under another user)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def remove_stale_siblings(final: Path) -> list[Path]:
    """Remove the staging and trash siblings of `final` (`.<name>.tmp-<pid>`,
    `.<name>.trash-<pid>`) that a killed run left: those whose process is gone. Returns them."""
    import shutil

    final = Path(final)
    removed: list[Path] = []
    if not final.parent.is_dir():
        return removed
    for entry in final.parent.iterdir():
        match = SIBLING.match(entry.name)
        if match is None or match["name"] != final.name:
            continue
        pid = int(match["pid"])
        if pid == os.getpid() or _alive(pid):
            continue
        if entry.is_dir() and not entry.is_symlink():
            shutil.rmtree(entry, ignore_errors=True)
        else:
            entry.unlink(missing_ok=True)
        removed.append(entry)
    return removed


def swap_into_place(new: Path, final: Path) -> None:
    """Replace the directory `final` by `new` with renames: old -> trash, new -> final, delete
    trash. A reader sees the old directory or the new one, never a mixture, whenever the
    process is killed (a killed run leaves at most a hidden staging or trash sibling)."""
    import shutil

    new, final = Path(new), Path(final)
    trash = final.parent / f".{final.name}.trash-{os.getpid()}"
    if trash.exists():
        shutil.rmtree(trash)
    if final.exists() or final.is_symlink():
        os.rename(final, trash)
    os.rename(new, final)
    if trash.is_dir() and not trash.is_symlink():
        shutil.rmtree(trash, ignore_errors=True)
    elif trash.exists() or trash.is_symlink():
        trash.unlink()
