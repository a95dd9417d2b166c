"""Track one float end to end: resolve inputs, configure, filter, write outputs.

`rafostrack track F.csv` looks for `beacons.csv`, `floats.csv` and `rafostrack.toml` next
to F; explicit paths and a launch position override them.
"""

from __future__ import annotations

import dataclasses
import errno
import re
import shutil
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .. import __version__
from ..config import Config, load_config
from ..domain import ArrivalRecord, FloatInfo
from ..errors import InputError, Notice, WarningKind, Warnings, kind_of, listing, nearest_id
from ..io import float_id_of, read_arrivals, read_beacons, read_floats
from ..io.outdir import check_output_dir, remove_stale_siblings, staging_dir, swap_into_place
from ..io.output_formats import write_estimate
from ..io.writers import file_digest, write_json
from ..problem import FloatProblem
from .method import TrackOutput, track_record
from .progress import NoProgress, Progress
from .resources import available_bytes, memory_warning

MISSION_CONFIG = "rafostrack.toml"
EARLIEST_TIME = np.datetime64("1678-01-01T00:00", "ns")  # the readers' earliest accepted time


@dataclass(frozen=True)
class TrackInputs:
    """Where a float's inputs live; `None` paths are looked up beside the float file."""

    float_path: Path
    beacons_path: Path | None = None
    floats_path: Path | None = None
    launch: tuple[float, float] | None = None
    config_files: tuple[Path, ...] = ()
    overrides: dict[str, dict[str, Any]] = field(default_factory=dict)
    input_format: str | None = None  # the arrival file's reader (`rafostrack.io`); None: by file type

    @property
    def mission_dir(self) -> Path:
        return self.float_path.parent

    @property
    def float_id(self) -> str:
        return float_id_of(self.float_path, self.input_format)

    def resolved_beacons(self) -> Path:
        """`--beacons`, else `beacons.csv` beside the float file, else an ARTOA `soso.dat` or
        single `*.soso` there."""
        if self.beacons_path is not None:
            return self.beacons_path
        default = self.mission_dir / "beacons.csv"
        if not default.exists():
            soso = [self.mission_dir / "soso.dat"] if (self.mission_dir / "soso.dat").is_file() else []
            soso = soso or sorted(self.mission_dir.glob("*.soso"))
            if len(soso) == 1:
                return soso[0]
        return default

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
    """One float read and configured: its problem (the keys the user set in its config), its
    arrival record, and what reading them warned of."""

    problem: FloatProblem
    record: ArrivalRecord
    warnings: Warnings


def load_float(inputs: TrackInputs) -> LoadedFloat:
    """Read, validate and configure everything needed to track one float."""
    if not inputs.float_path.is_file():
        raise InputError(f"{inputs.float_path}: file not found")
    config = load_config(inputs.config_layers(), inputs.overrides)
    beacons = read_beacons(inputs.resolved_beacons())
    warnings = Warnings()
    floats_path = inputs.resolved_floats()
    if floats_path is None:  # --launch without floats.csv: launched at the first window
        info = _info_from_launch(inputs.float_id, inputs.launch, config)
        record = read_arrivals(inputs.float_path, info, beacons, warnings, inputs.input_format)
        info = dataclasses.replace(info, launch_time=record.windows[0].time)
    else:
        info = _float_info(floats_path, inputs, config)
        record = read_arrivals(inputs.float_path, info, beacons, warnings, inputs.input_format)
    if config.filter.likelihood == "labeled" and not record.has_labels:
        raise InputError(f"{inputs.float_path}: likelihood 'labeled' needs a 'beacon_id' column of known labels")
    return LoadedFloat(FloatProblem(beacons, info, config), record, warnings)


def _float_info(floats_path: Path, inputs: TrackInputs, config: Config) -> FloatInfo:
    if not floats_path.exists():
        raise InputError(
            f"{floats_path}: file not found; expected a float table (float_id, launch_time, launch_lat, launch_lon) "
            "beside the float file, or give --floats FILE, or --launch LAT,LON to start from a launch position"
        )
    floats = read_floats(floats_path, config.model)
    float_id = _match_float_id(inputs.float_id, floats)
    if float_id not in floats:
        raise InputError(
            f"{floats_path}: no row for float_id {inputs.float_id!r} (the arrival file's name)"
            f"{nearest_id(inputs.float_id, floats)}; known: {listing(sorted(floats)) or 'none'}"
        )
    info = floats[float_id]
    if inputs.launch is not None:
        info = dataclasses.replace(info, launch_lat=inputs.launch[0], launch_lon=inputs.launch[1])
    return info


def _match_float_id(name: str, floats: dict[str, FloatInfo]) -> str:
    """`name` itself when floats.csv has it, else the one row whose id carries the same number
    (`rf0767toa.mat` names float `767`, which finds `float767`), else `name`."""
    if name in floats:
        return name
    digits = re.sub(r"\D", "", name)
    if not digits:
        return name
    same = [f for f in floats if re.sub(r"\D", "", f) and int(re.sub(r"\D", "", f)) == int(digits)]
    return same[0] if len(same) == 1 else name


def _info_from_launch(float_id: str, launch: tuple[float, float] | None, config: Config) -> FloatInfo:
    """The float's description from `--launch` alone; its launch time is set to the first
    window's once the file is read (here: the earliest time the readers accept)."""
    if launch is None:
        raise InputError(f"{float_id}: no floats.csv and no --launch LAT,LON; expected one of them")
    nat = np.datetime64("NaT", "ns")
    return FloatInfo(
        float_id=float_id,
        launch_time=EARLIEST_TIME,
        launch_lat=launch[0],
        launch_lon=launch[1],
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
    output: TrackOutput
    run: dict[str, Any]


def track_float(
    inputs: TrackInputs,
    out_root: Path,
    *,
    plots: bool = True,
    also_filtered: bool = False,
    progress: Progress | None = None,
    formats: tuple[str, ...] = ("parquet",),
    notice: Callable[[str], None] | None = None,
) -> TrackResult:
    """Track one float and write `out_root/<float_id>/`: Parquet tables, plots, run.json.
    `notice` is told, before tracking, of a run the machine's memory may not hold
    (`run.resources`); the warning goes into run.json too.

    `track.parquet`, `labels.parquet` and `modes.parquet` hold the smoothed estimate (the
    filtered one when the smoother is off; their metadata `estimate` says which);
    `also_filtered` adds `*_filtered.parquet` beside them; `formats` chooses among parquet,
    csv, netcdf and rfc (`io.output_formats`). The directory is built in a
    hidden sibling and swapped in whole (`io.outdir.swap_into_place`): it holds exactly
    this run's files, and a run that fails or is killed leaves the previous one untouched.
    `run.json`'s `runtime_s` covers the whole run, plots included.
    """
    started = time.perf_counter()
    progress = progress or NoProgress()
    check_output_dir(Path(out_root))
    progress.phase("reading inputs")
    loaded = load_float(inputs)
    final = _float_dir(Path(out_root), loaded.problem.info.float_id)
    too_big = memory_warning(loaded.problem.config.filter.particles, len(loaded.record.windows), available_bytes())
    if too_big is not None and notice is not None:
        notice(too_big)
    progress.phase("tracking")
    output = track_record(loaded.problem, loaded.record, also_filtered=also_filtered, progress=progress.step)
    track_s = time.perf_counter() - started
    staging = staging_dir(final)
    stale = [
        Notice(WarningKind.OTHER, f"removed {path} (left by an interrupted run)")
        for path in remove_stale_siblings(final)
    ]
    warnings = [*([too_big] if too_big is not None else []), *output.warnings, *stale]
    try:
        if staging.exists():
            shutil.rmtree(staging)
        staging.mkdir(parents=True)
        _write_outputs(
            staging, loaded.problem, output, progress, plots=plots, also_filtered=also_filtered, formats=formats
        )
        run = run_record(inputs, loaded, output, time.perf_counter() - started, warnings)
        run["track_s"] = round(track_s, 3)
        write_json(staging / "run.json", run)
        swap_into_place(staging, final)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return TrackResult(loaded.problem.info.float_id, final, output, run)


def _float_dir(out_root: Path, float_id: str) -> Path:
    """`out_root/<float_id>`, the float's output directory; an error when a file is in its way
    (a user's file is never replaced by a result directory)."""
    final = out_root / float_id
    if final.exists() and not final.is_dir():
        raise NotADirectoryError(
            errno.ENOTDIR, "in the way of the float's output directory (not a directory)", str(final)
        )
    return final


def _write_outputs(
    out_dir: Path,
    problem: FloatProblem,
    output: TrackOutput,
    progress: Progress,
    *,
    plots: bool,
    also_filtered: bool,
    formats: tuple[str, ...],
) -> None:
    """The estimate's tables (`write_tables`) and, when asked for, its plots, into `out_dir`."""
    progress.phase("writing outputs")
    write_tables(out_dir, output, problem.config, problem.info, also_filtered=also_filtered, formats=formats)
    if plots:
        progress.phase("drawing plots")
        from .. import plots as plotting

        plotting.write_plots(out_dir, output.estimate, problem.beacons, problem.info, problem.config.model)


def write_tables(
    out_dir: Path,
    output: TrackOutput,
    config: Config,
    info: FloatInfo,
    *,
    also_filtered: bool = False,
    formats: tuple[str, ...] = ("parquet",),
) -> list[Path]:
    """The estimate's tables (and the filtered ones when asked for) in each of `formats`
    (`io.output_formats`), with the run's metadata."""
    estimates = [(output.estimate, "")]
    if also_filtered and output.filtered is not None and output.filtered is not output.estimate:
        estimates.append((output.filtered, "_filtered"))
    written = []
    for estimate, suffix in estimates:
        meta = {
            "version": __version__,
            "likelihood": config.filter.likelihood,
            "engine": config.filter.engine,
            "motion": config.motion.model,
            "estimate": estimate.kind,
            "config": config.to_dict(),
        }
        tables = {"track": estimate.track, "labels": estimate.labels, "modes": estimate.modes}
        written += write_estimate(out_dir, tables, info, formats, meta, suffix)
    return written


def run_record(
    inputs: TrackInputs,
    loaded: LoadedFloat,
    output: TrackOutput,
    elapsed_s: float,
    warnings: Sequence[str] | None = None,
) -> dict[str, Any]:
    """The `run.json` payload: version, inputs with digests, config, method, runtime, counts;
    the warnings of reading the inputs, then `warnings` (by default the method's), each
    with its kind (`warning_kinds`, in the same order)."""
    warned = [*loaded.warnings.messages, *(output.warnings if warnings is None else warnings)]
    files = {"float_file": inputs.float_path, "beacons": inputs.resolved_beacons()}
    floats_path = inputs.resolved_floats()
    if floats_path is not None:
        files["floats"] = floats_path
    labels = output.labels
    config = loaded.problem.config
    return {
        "rafostrack_version": __version__,
        "float_id": loaded.problem.info.float_id,
        "likelihood": config.filter.likelihood,
        "engine": config.filter.engine,
        "motion": config.motion.model,
        "estimate": output.estimate.kind,
        "smoother": output.smoother,
        "inputs": {k: {"path": str(p), "sha256": file_digest(p)} for k, p in files.items()},
        "config_files": [str(p) for p in inputs.config_layers()],
        "config": config.to_dict(),
        "runtime_s": round(elapsed_s, 3),
        "filter_s": round(output.seconds.filter_s, 3),
        "smoother_s": round(output.seconds.smoother_s, 3),
        "calibrate_s": round(output.seconds.calibrate_s, 3),
        "calibration": output.calibration,
        "metadata_checks": list(output.metadata_checks),
        "ess": _ess_summary(np.array(output.counts.filter_ess), config.filter.particles),
        "counts": {
            "windows": len(output.track),
            "toas": len(labels),
            "labelled_beacon": int(labels["beacon_id"].notna().sum()),
            "labelled_clutter": int(labels["beacon_id"].isna().sum()),
            "resamples": output.counts.n_resamples,
            "recovery_checks": output.counts.n_checks,
            "recovery_reseeds": output.counts.n_reseeds,
            "ambiguous_windows": int(output.track["ambiguous"].sum()),
            "status": {k: int(v) for k, v in output.track["status"].value_counts().sort_index().items()},
            "warnings": len(warned),
        },
        "warnings": warned,
        "warning_kinds": [kind_of(message) for message in warned],
    }


def _ess_summary(ess: np.ndarray, particles: int) -> dict[str, float]:
    """The filter's effective sample size over the windows: median, 10th percentile, minimum,
    and the median as a fraction of the particles."""
    if len(ess) == 0:
        return {}
    return {
        "median": round(float(np.median(ess)), 1),
        "p10": round(float(np.percentile(ess, 10)), 1),
        "min": round(float(ess.min()), 1),
        "median_fraction": round(float(np.median(ess)) / particles, 3),
    }
