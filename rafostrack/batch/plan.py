"""Decide, for every float, whether it must be tracked and why: keys, manifests, what changed.

Guarantees:

- Each float gets a key, the SHA-256 over its arrival file's bytes, the bytes of its
  mission's `beacons.csv`, its own row of `floats.csv`, the effective configuration (every
  layer, loaded as `track` loads it: the values and which keys a layer sets, since a key
  the user set is not calibrated, `Config.explicit`), the package version and the plots
  option. Paths are not hashed: an output tree can be moved with its inputs.
- A float is skipped only when its output directory holds a `batch-manifest.json` with the
  same key and every file the manifest lists is there with its recorded size. Otherwise it
  becomes a task whose `why` names what changed (`float file changed`, `beacons.csv
  changed`, `config changed`, ...), or `new`, `forced`, `outputs incomplete`.
- Floats that cannot run (unreadable `floats.csv` or `beacons.csv`, a bad mission config, a
  float id that cannot name a directory) fail here with a one-line reason; a listed float
  without its arrival file is skipped (not recovered yet). Nothing here writes.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .. import __version__
from ..config import Config, load_config
from ..errors import InputError
from ..io.writers import file_digest
from .discover import Mission
from .lock import LOCK_INFO_NAME

MANIFEST = "batch-manifest.json"
MANIFEST_FORMAT = 1

PROCESSED, SKIPPED, FAILED = "processed", "skipped", "failed"


@dataclass(frozen=True)
class FloatTask:
    """Everything a worker needs to track one float and install its outputs (picklable)."""

    mission: str
    float_id: str
    float_path: Path
    out_dir: Path  # OUT/<mission>/<float_id>, the final location
    config_files: tuple[Path, ...]
    overrides: dict[str, dict[str, Any]]
    plots: bool
    key: str
    components: dict[str, Any]
    why: str  # why it is (re)processed: "new", "float file changed", "forced", ...
    lock_info_path: Path  # OUT/.rafostrack-batch.lock.json: names the run holding OUT's lock
    run_id: str  # this run's id: a worker installs outputs only while the lock info names it
    beacons_path: Path | None = None  # the table tracked with, when not the mission's beacons.csv


@dataclass
class FloatOutcome:
    """What became of one float: one row of batch-summary.csv."""

    mission: str
    float_id: str
    status: str  # processed / skipped / failed
    reason: str = ""
    seconds: float | None = None
    warnings: int | None = None
    output: str = ""
    detail: str = ""  # traceback of an unexpected exception, for batch.log

    def row(self) -> dict[str, Any]:
        seconds = "" if self.seconds is None else f"{self.seconds:.2f}"
        warnings = "" if self.warnings is None else self.warnings
        return dict(
            mission=self.mission,
            float_id=self.float_id,
            status=self.status,
            reason=self.reason,
            seconds=seconds,
            warnings=warnings,
            output=self.output,
        )


_COMPONENT_NAMES = {
    "float_file_sha256": "float file changed",
    "beacons_sha256": "beacons.csv changed",
    "floats_row_sha256": "floats.csv row changed",
    "config_sha256": "config changed",
    "rafostrack_version": "package version changed",
    "plots": "plots option changed",
}


def _sha256_json(value: Any) -> str:
    return hashlib.sha256(json.dumps(value, sort_keys=True, default=str).encode()).hexdigest()


def read_manifest(out_dir: Path) -> dict[str, Any] | None:
    """The float directory's manifest, or None when it is missing or unreadable."""
    try:
        data = json.loads((out_dir / MANIFEST).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def _is_complete(out_dir: Path, manifest: dict[str, Any]) -> bool:
    files = manifest.get("files")
    if not isinstance(files, dict) or not files:
        return False
    for name, size in files.items():
        try:
            if (out_dir / name).stat().st_size != size:
                return False
        except OSError:
            return False
    return True


def _why(out_dir: Path, key: str, components: dict[str, Any], force: bool) -> str | None:
    """None when the outputs are complete and made from the same inputs; else the reason."""
    manifest = read_manifest(out_dir)
    if manifest is None:
        if out_dir.exists():
            return "no batch manifest (incomplete, or written by another command)"
        return "new"
    if manifest.get("key") != key:
        old = manifest.get("components") or {}
        changed = [text for name, text in _COMPONENT_NAMES.items() if old.get(name) != components.get(name)]
        return ", ".join(changed) or "inputs changed"
    if not _is_complete(out_dir, manifest):
        return "outputs incomplete (a file listed in the manifest is missing or changed)"
    return "forced" if force else None


@dataclass(frozen=True)
class _Batch:
    """What every float of one plan shares: OUT, the batch's config layers and options."""

    out: Path
    config_files: tuple[Path, ...]
    overrides: dict[str, dict[str, Any]]
    plots: bool
    force: bool
    run_id: str
    beacons_of: Mapping[str, Path]


def plan(
    missions: Sequence[Mission],
    out: Path,
    *,
    config_files: tuple[Path, ...] = (),
    overrides: dict[str, dict[str, Any]] | None = None,
    plots: bool = True,
    force: bool = False,
    run_id: str = "",
    beacons_of: Mapping[str, Path] | None = None,
) -> tuple[list[FloatTask], list[FloatOutcome]]:
    """Split every float into work to do (tasks) and outcomes known now (skipped, or failed
    before running: unreadable floats.csv, bad mission config, missing arrival file).
    `beacons_of`: per mission name, the table its floats are tracked with instead of its
    beacons.csv (the mission's calibrated array); its bytes are in the floats' keys, and
    those floats release no source value on their own arrivals (`_with_mission_checks`)."""
    batch = _Batch(Path(out).resolve(), tuple(config_files), overrides or {}, plots, force, run_id, beacons_of or {})
    tasks: list[FloatTask] = []
    known: list[FloatOutcome] = []
    for mission in missions:
        beacons_sha, beacons_error = _beacons_digest(batch.beacons_of.get(mission.name, mission.path / "beacons.csv"))
        for float_id, row in sorted(mission.rows.items()):
            decided = _plan_float(mission, float_id, row, beacons_sha, beacons_error, batch)
            if isinstance(decided, FloatTask):
                tasks.append(decided)
            else:
                known.append(decided)
    return tasks, known


def _beacons_digest(path: Path) -> tuple[str, str]:
    """The SHA-256 of a mission's beacon table and "", or "" and why it cannot be read."""
    try:
        return file_digest(path), ""
    except OSError as exc:
        return "", f"{path}: cannot read: {exc.strerror or exc}"


def _plan_float(
    mission: Mission, float_id: str, row: dict[str, str], beacons_sha: str, beacons_error: str, batch: _Batch
) -> FloatTask | FloatOutcome:
    """One float's task (with its key and why it is tracked), or its outcome known now."""
    from ..run.one_float import TrackInputs

    float_path = mission.path / f"{float_id}.csv"
    out_dir = batch.out / mission.name / float_id
    fail = _known_failure(mission, float_id, float_path, beacons_error)
    if fail is not None:
        status, reason = fail
        return FloatOutcome(mission.name, float_id, status, reason)
    overrides = _with_mission_checks(batch.overrides) if mission.name in batch.beacons_of else batch.overrides
    inputs = TrackInputs(float_path=float_path, config_files=batch.config_files, overrides=overrides)
    try:
        config = load_config(inputs.config_layers(), inputs.overrides)
        float_sha = file_digest(float_path)
    except InputError as exc:
        return FloatOutcome(mission.name, float_id, FAILED, str(exc))
    except OSError as exc:
        return FloatOutcome(mission.name, float_id, FAILED, f"{float_path}: {exc.strerror or exc}")
    components = {
        "float_file_sha256": float_sha,
        "beacons_sha256": beacons_sha,
        "floats_row_sha256": _sha256_json(row),
        "config_sha256": _sha256_json(config_identity(config)),
        "rafostrack_version": __version__,
        "plots": bool(batch.plots),
    }
    key = _sha256_json({"format": MANIFEST_FORMAT, **components})
    why = _why(out_dir, key, components, batch.force)
    if why is None:
        return FloatOutcome(mission.name, float_id, SKIPPED, "unchanged", output=str(out_dir))
    return FloatTask(
        mission=mission.name,
        float_id=float_id,
        float_path=float_path,
        out_dir=out_dir,
        config_files=batch.config_files,
        overrides=overrides,
        plots=batch.plots,
        key=key,
        components=components,
        why=why,
        lock_info_path=batch.out / LOCK_INFO_NAME,
        run_id=batch.run_id,
        beacons_path=batch.beacons_of.get(mission.name),
    )


def _with_mission_checks(overrides: dict[str, dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """The overrides of a float tracked with its mission's calibrated table: no source value
    released on its own arrivals (`[checks] release_sources`): the mission's array fit
    judged every source on all the floats hearing it."""
    return {**overrides, "checks": {**overrides.get("checks", {}), "release_sources": False}}


def config_identity(config: Config) -> dict[str, Any]:
    """What of a configuration decides a float's outputs: every value, and the keys the user
    set (calibration keeps those as set, so setting a key to its default value matters)."""
    return {"values": config.to_dict(), "explicit": sorted(f"[{s}] {k}" for s, k in config.explicit)}


def _known_failure(mission: Mission, float_id: str, float_path: Path, beacons_error: str) -> tuple[str, str] | None:
    if mission.error is not None:
        return FAILED, mission.error
    if beacons_error:
        return FAILED, beacons_error
    if float_id in ("", ".", "..") or float_id.startswith(".") or any(c in float_id for c in "/\\"):
        return FAILED, f"{mission.path / 'floats.csv'}: float_id {float_id!r} cannot name an output directory"
    if not float_path.is_file():
        # Listed but not (yet) there: e.g. a float not recovered yet. Not a failure.
        return SKIPPED, f"no arrival file {float_path.name} (listed in floats.csv)"
    return None
