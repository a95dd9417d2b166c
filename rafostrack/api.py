"""The Python API: `rafostrack.track(...)`, for notebooks and scripts.

    import rafostrack
    r = rafostrack.track("data/samples/float767.csv", particles=500)
    r.track.head(); r.labels; r.run_info["counts"]; r.plot()

A float is given as a file (any registered arrival format, with `beacons.csv` and
`floats.csv` found beside it as for `rafostrack track`) or as DataFrames in the CSV
columns (docs/user-guide.md, "Inputs"), which are checked exactly as files are (they are written to a
temporary mission directory and read back by the same readers). Configuration keys are
keyword arguments: a key's bare name when only one section has it (`particles=500`,
`p_detect=0.8`), else `<section>_<key>` (`calibrate_enabled=False`); `smooth=False` turns the
smoother off; `config={"section": {"key": value}}` and `config_file=` add whole layers.
Nothing is written unless `out=` names a directory (then exactly what `rafostrack track`
writes there).
"""

from __future__ import annotations

import dataclasses
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from .config import SECTIONS
from .errors import InputError, nearest
from .problem import FloatProblem
from .run.one_pass import TrackOutput


def _flat_keys() -> dict[str, tuple[str, str]]:
    """Keyword name -> (section, key): bare names that one section alone has, and every
    `<section>_<key>`."""
    owners: dict[str, list[str]] = {}
    for section, cls in SECTIONS.items():
        for f in dataclasses.fields(cls):
            owners.setdefault(f.name, []).append(section)
    flat = {k: (s[0], k) for k, s in owners.items() if len(s) == 1}
    for section, cls in SECTIONS.items():
        for f in dataclasses.fields(cls):
            flat[f"{section}_{f.name}"] = (section, f.name)
    flat["smooth"] = ("smoother", "enabled")
    return flat


def config_overrides(options: dict[str, Any], config: dict[str, dict[str, Any]] | None = None) -> dict[str, dict]:
    """Nested overrides from keyword options (module docstring) on top of `config`."""
    flat = _flat_keys()
    out: dict[str, dict[str, Any]] = {s: dict(v) for s, v in (config or {}).items()}
    for name, value in options.items():
        if name not in flat:
            hint = nearest(name, flat) or " (a config key, or <section>_<key>)"
            raise InputError(f"rafostrack.track: unknown option {name!r}{hint}")
        section, key = flat[name]
        out.setdefault(section, {})[key] = value
    return out


@dataclass(frozen=True)
class TrackRun:
    """One float tracked: its tables, the run's record and what `.plot()` needs."""

    float_id: str
    track: pd.DataFrame
    labels: pd.DataFrame
    modes: pd.DataFrame
    run_info: dict[str, Any]
    output: TrackOutput
    problem: FloatProblem  # the float's beacons, description and configuration, as loaded
    out_dir: Path | None = None

    def plot(self, kind: str = "track", path: str | Path | None = None, **extra: Any):
        """A matplotlib Figure of `kind` ("track", "arrivals" or "uncertainty"), also written
        as a PNG when `path` is given. `extra`: `truth` and `background` for the map."""
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        from .plots import base, draw_arrivals, draw_track, draw_uncertainty

        fig = Figure(figsize=base.FIGSIZE, dpi=base.DPI, layout="constrained")
        FigureCanvasAgg(fig)
        beacons, info = self.problem.beacons, self.problem.info
        if kind == "track":
            draw_track(fig, self.track, beacons, info, extra.get("truth"), self.modes, extra.get("background"))
        elif kind == "arrivals":
            draw_arrivals(fig, self.labels, self.track, beacons, info, self.problem.config.model)
        elif kind == "uncertainty":
            draw_uncertainty(fig, self.track)
        else:
            raise ValueError(f"unknown plot {kind!r}: expected track, arrivals or uncertainty")
        if path is not None:
            base.save_png(fig, Path(path))
        return fig


def track(
    source: str | Path | pd.DataFrame,
    *,
    beacons: str | Path | pd.DataFrame | None = None,
    floats: str | Path | pd.DataFrame | None = None,
    launch: tuple[float, float] | None = None,
    float_id: str | None = None,
    config: dict[str, dict[str, Any]] | None = None,
    config_file: str | Path | None = None,
    out: str | Path | None = None,
    plots: bool = True,
    formats: tuple[str, ...] = ("parquet",),
    input_format: str | None = None,
    **options: Any,
) -> TrackRun:
    """Track one float (module docstring) and return its `TrackRun`: `.track`, `.labels`,
    `.modes` (DataFrames), `.run_info` (what run.json holds) and `.plot()`. With `out`, also
    write `out/<float_id>/` as `rafostrack track` does (`plots`, `formats`)."""
    overrides = config_overrides(options, config)
    config_files = (Path(config_file),) if config_file is not None else ()
    frames = {"arrivals": source, "beacons": beacons, "floats": floats}
    if any(isinstance(v, pd.DataFrame) for v in frames.values()):
        with tempfile.TemporaryDirectory(prefix="rafostrack-") as tmp:
            paths = _write_frames(Path(tmp), frames, float_id)
            run = _track_files(paths, launch, config_files, overrides, out, plots, formats, input_format)
        return dataclasses.replace(run, run_info={**run.run_info, "inputs": {"from": "DataFrames"}})
    paths = {k: (None if v is None else Path(v)) for k, v in frames.items()}
    return _track_files(paths, launch, config_files, overrides, out, plots, formats, input_format)


def _write_frames(tmp: Path, frames: dict[str, Any], float_id: str | None) -> dict[str, Path | None]:
    """DataFrames as a CSV mission in `tmp` (files stay files); returns the paths to read."""
    from .io.output_formats import write_csv

    floats = frames["floats"]
    if float_id is None:
        ids = list(floats["float_id"].astype(str)) if isinstance(floats, pd.DataFrame) else []
        float_id = ids[0] if len(ids) == 1 else "float"
    paths: dict[str, Path | None] = {}
    for kind, name in (("arrivals", f"{float_id}.csv"), ("beacons", "beacons.csv"), ("floats", "floats.csv")):
        value = frames[kind]
        if isinstance(value, pd.DataFrame):
            write_csv(value, tmp / name)
            paths[kind] = tmp / name
        else:
            paths[kind] = None if value is None else Path(value)
    return paths


def _track_files(
    paths: dict[str, Path | None],
    launch: tuple[float, float] | None,
    config_files: tuple[Path, ...],
    overrides: dict[str, dict[str, Any]],
    out: str | Path | None,
    plots: bool,
    formats: tuple[str, ...],
    input_format: str | None,
) -> TrackRun:
    from .run.method import track_record
    from .run.one_float import TrackInputs, load_float, run_record, track_float

    arrivals = paths["arrivals"]
    assert arrivals is not None
    inputs = TrackInputs(
        float_path=arrivals,
        beacons_path=paths["beacons"],
        floats_path=paths["floats"],
        launch=launch,
        config_files=config_files,
        overrides=overrides,
        input_format=input_format,
    )
    loaded = load_float(inputs)
    if out is not None:
        result = track_float(inputs, Path(out), plots=plots, formats=formats)
        output, run, out_dir = result.output, result.run, result.out_dir
    else:
        started = time.perf_counter()
        output = track_record(loaded.problem, loaded.record)
        run, out_dir = run_record(inputs, loaded, output, time.perf_counter() - started), None
    est = output.estimate
    return TrackRun(
        loaded.problem.info.float_id, est.track, est.labels, est.modes, run, output, loaded.problem, out_dir
    )
