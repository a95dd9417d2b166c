"""Track one float end to end: resolve inputs, configure, filter, write outputs.

`rafostrack track F.csv` looks for `beacons.csv`, `floats.csv` and `rafostrack.toml` next
to F; explicit paths and a launch position override them.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from . import __version__
from .config import Config, load_config
from .errors import InputError, Warnings
from .filter import FilterOutput, ParticleFilter, float_rng
from .inputs import ArrivalRecord, BeaconTable, FloatInfo, read_arrivals, read_beacons, read_floats
from .outputs import file_digest, write_json, write_parquet

MISSION_CONFIG = "rafostrack.toml"


@dataclass(frozen=True)
class TrackInputs:
    """Where a float's inputs live; `None` paths are looked up beside the float file."""

    float_path: Path
    beacons_path: Path | None = None
    floats_path: Path | None = None
    launch: tuple[float, float] | None = None
    config_files: tuple[Path, ...] = ()
    overrides: dict[str, dict[str, Any]] = field(default_factory=dict)

    @property
    def mission_dir(self) -> Path:
        return self.float_path.parent

    @property
    def float_id(self) -> str:
        return self.float_path.stem

    def resolved_beacons(self) -> Path:
        return self.beacons_path or self.mission_dir / "beacons.csv"

    def resolved_floats(self) -> Path | None:
        path = self.floats_path or self.mission_dir / "floats.csv"
        if self.floats_path is None and self.launch is not None and not path.exists():
            return None
        return path

    def config_layers(self) -> tuple[Path, ...]:
        mission = self.mission_dir / MISSION_CONFIG
        return ((mission,) if mission.is_file() else ()) + tuple(self.config_files)


@dataclass(frozen=True)
class LoadedFloat:
    config: Config
    beacons: BeaconTable
    info: FloatInfo
    record: ArrivalRecord
    warnings: Warnings


def load_float(inputs: TrackInputs) -> LoadedFloat:
    """Read, validate and configure everything needed to track one float."""
    if not inputs.float_path.is_file():
        raise InputError(f"{inputs.float_path}: file not found")
    config = load_config(inputs.config_layers(), inputs.overrides)
    beacons = read_beacons(inputs.resolved_beacons())
    info = _float_info(inputs, config)
    warnings = Warnings()
    record = read_arrivals(inputs.float_path, info, beacons, warnings)
    if config.filter.method == "labeled" and not record.has_labels:
        raise InputError(f"{inputs.float_path}: method 'labeled' needs a 'beacon_id' column of known labels")
    return LoadedFloat(config, beacons, info, record, warnings)


def _float_info(inputs: TrackInputs, config: Config) -> FloatInfo:
    floats_path = inputs.resolved_floats()
    if floats_path is None:  # --launch without floats.csv: launch at the first window
        return _info_from_launch(inputs, config)
    floats = read_floats(floats_path, config.model)
    if inputs.float_id not in floats:
        raise InputError(
            f"{floats_path}: no row for float_id {inputs.float_id!r} (the arrival file's name); "
            f"known: {', '.join(sorted(floats)) or 'none'}"
        )
    info = floats[inputs.float_id]
    if inputs.launch is not None:
        info = FloatInfo(**{**info.__dict__, "launch_lat": inputs.launch[0], "launch_lon": inputs.launch[1]})
    return info


def _info_from_launch(inputs: TrackInputs, config: Config) -> FloatInfo:
    import pandas as pd

    from .inputs import parse_time_column, read_csv_table

    frame = read_csv_table(inputs.float_path, ("time", "toa_s"), ("quality", "beacon_id"))
    times = parse_time_column(inputs.float_path, frame, "time")
    if len(times) == 0:
        raise InputError(f"{inputs.float_path}: no arrival times (header only)")
    nat = np.datetime64("NaT", "ns")
    return FloatInfo(
        float_id=inputs.float_id,
        launch_time=pd.Timestamp(times.min()).to_datetime64(),
        launch_lat=inputs.launch[0],
        launch_lon=inputs.launch[1],
        end_time=nat,
        end_lat=np.nan,
        end_lon=np.nan,
        clock_offset_start_s=0.0,
        clock_offset_end_s=0.0,
        window_s=config.model.window_s,
        max_signals=config.model.max_signals,
    )


@dataclass(frozen=True)
class TrackResult:
    float_id: str
    out_dir: Path
    output: FilterOutput
    run: dict[str, Any]


def track_float(inputs: TrackInputs, out_root: Path, *, plots: bool = True) -> TrackResult:
    """Track one float and write `out_root/<float_id>/`: Parquet tables, plots, run.json."""
    started = time.perf_counter()
    loaded = load_float(inputs)
    config = loaded.config
    pf = ParticleFilter(loaded.beacons, loaded.info, config)
    output = pf.run(loaded.record, float_rng(config.filter.seed, loaded.info.float_id))
    elapsed = time.perf_counter() - started

    out_dir = Path(out_root) / loaded.info.float_id
    meta = {"version": __version__, "method": config.filter.method, "config": config.to_dict()}
    write_parquet(output.track, out_dir / "track.parquet", meta)
    write_parquet(output.labels, out_dir / "labels.parquet", meta)
    if plots:
        from .plots import write_plots

        write_plots(out_dir, output.track, output.labels, loaded.beacons, loaded.info, config.model)
    run = run_record(inputs, loaded, output, elapsed)
    write_json(out_dir / "run.json", run)
    return TrackResult(loaded.info.float_id, out_dir, output, run)


def run_record(inputs: TrackInputs, loaded: LoadedFloat, output: FilterOutput, elapsed_s: float) -> dict[str, Any]:
    """The `run.json` payload: version, inputs with digests, config, method, runtime, counts."""
    files = {"float_file": inputs.float_path, "beacons": inputs.resolved_beacons()}
    floats_path = inputs.resolved_floats()
    if floats_path is not None:
        files["floats"] = floats_path
    labels = output.labels
    return {
        "rafostrack_version": __version__,
        "float_id": loaded.info.float_id,
        "method": loaded.config.filter.method,
        "inputs": {k: {"path": str(p), "sha256": file_digest(p)} for k, p in files.items()},
        "config_files": [str(p) for p in inputs.config_layers()],
        "config": loaded.config.to_dict(),
        "runtime_s": round(elapsed_s, 3),
        "counts": {
            "windows": len(output.track),
            "toas": len(labels),
            "labelled_beacon": int(labels["beacon_id"].notna().sum()),
            "labelled_clutter": int(labels["beacon_id"].isna().sum()),
            "resamples": output.n_resamples,
            "warnings": len(loaded.warnings),
        },
        "warnings": list(loaded.warnings.messages),
    }
