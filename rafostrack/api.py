"""The Python API: `rafostrack.track(...)`, for notebooks and scripts.

    import rafostrack
    r = rafostrack.track("data/samples/float767.csv", particles=500)
    r.track.head(); r.labels; r.run_info["counts"]; r.plot()

A float is given as a file (any registered arrival format, with `beacons.csv` and
`floats.csv` found beside it as for `rafostrack track`) or as DataFrames in the CSV
columns (docs/user-guide.md, "Inputs"), which are checked exactly as files are (they are written to a
temporary mission directory and read back by the same readers); a message then names the
argument and the row by its index label (`floats DataFrame: row 2: field 'launch_lat': ...`),
not the temporary file. The arrivals DataFrame may also carry a `float_id` column (the
arrivals of several floats: `float_id=` picks one). Which float a DataFrame of arrivals
belongs to: `float_id=`, else the arrivals' own `float_id` column, else the floats table's
only row; a floats table of several floats without either is an error naming them. The
returned tables' `time` columns are UTC (tz-aware), as in the Parquet files.

Configuration keys are keyword arguments: a key's bare name when only one section has it
(`particles=500`, `p_detect=0.8`), else `<section>_<key>` (`calibrate_enabled=False`);
`smooth=False` turns the smoother off; `config={"section": {"key": value}}` and
`config_file=` add whole layers.
Nothing is written unless `out=` names a directory (then exactly what `rafostrack track`
writes there).
"""

from __future__ import annotations

import dataclasses
import functools
import re
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from .config import SECTIONS
from .errors import InputError, listing, nearest, nearest_id
from .problem import FloatProblem
from .run.method import TrackOutput


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
        est = self.output.estimate  # the tables as the plots of `rafostrack track` get them (times naive UTC)
        if kind == "track":
            draw_track(fig, est.track, beacons, info, extra.get("truth"), est.modes, extra.get("background"))
        elif kind == "arrivals":
            draw_arrivals(fig, est.labels, est.track, beacons, info, self.problem.config.model)
        elif kind == "uncertainty":
            draw_uncertainty(fig, est.track)
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
            mission = _write_frames(Path(tmp), frames, float_id, launch)
            try:
                run = _track_files(mission.paths, launch, config_files, overrides, out, plots, formats, input_format)
            except InputError as exc:
                raise InputError(mission.name_frames(str(exc))) from None
        warnings = [mission.name_frames(m) for m in run.run_info["warnings"]]
        run_info = {**run.run_info, "inputs": {"from": "DataFrames"}, "warnings": warnings}
        if run.out_dir is not None:  # run.json as returned: no temporary file named
            from .io.writers import write_json

            write_json(run.out_dir / "run.json", run_info)
        return dataclasses.replace(run, run_info=run_info)
    from .io import check_arrival_file

    check_arrival_file(Path(source))
    paths = {k: (None if v is None else Path(v)) for k, v in frames.items()}
    return _track_files(paths, launch, config_files, overrides, out, plots, formats, input_format)


@dataclass(frozen=True)
class _FrameMission:
    """DataFrames written as a CSV mission: the paths to read, and per written file the
    argument and the DataFrame as written, so that a message names those, not the file."""

    paths: dict[str, Path | None]
    written: dict[str, tuple[str, pd.DataFrame]]  # str(path) -> (argument, frame as written)

    def name_frames(self, message: str) -> str:
        """`message` with each written file named by its argument (`arrivals DataFrame`) and
        each of its lines by the row's index label (line 1, the header, is `columns`)."""
        present = [path for path in self.written if path in message]
        for path in present:
            argument, frame = self.written[path]
            if len(present) == 1:  # every line the message cites is this file's
                message = re.sub(r"\bline (\d+)\b", functools.partial(_row_of_match, frame, ""), message)
            else:
                pattern = re.escape(path) + r": line (\d+)\b"
                message = re.sub(pattern, functools.partial(_row_of_match, frame, f"{path}: "), message)
            message = message.replace(path, f"{argument} DataFrame")
        return message


def _row_of_match(frame: pd.DataFrame, prefix: str, match: re.Match[str]) -> str:
    return prefix + _row_name(frame, int(match[1]))


def _row_name(frame: pd.DataFrame, line: int) -> str:
    """What line `line` of `frame` written as CSV is: `columns` (the header), else `row <index label>`."""
    position = line - 2
    if position < 0:
        return "columns"
    if position >= len(frame):
        return f"line {line}"
    label = frame.index[position]
    return f"row {label}" if hasattr(label, "__index__") else f"row '{label}'"  # an integer label bare


def _write_frames(
    tmp: Path, frames: dict[str, Any], float_id: str | None, launch: tuple[float, float] | None
) -> _FrameMission:
    """DataFrames as a CSV mission in `tmp` (files stay files): the arrivals as
    `<float_id>.csv` (`_frames_float_id`), without a `float_id` column. Arrivals given as a
    DataFrame with no beacons (or no floats and no launch) are an error here: those would
    be looked for beside the arrivals, in `tmp`."""
    arrivals, floats = frames["arrivals"], frames["floats"]
    if isinstance(arrivals, pd.DataFrame):
        tables = (("beacons", "beacon_id, lat, lon"), ("floats", "float_id, launch_time, launch_lat, launch_lon"))
        for kind, expected in tables:
            if frames[kind] is None and (kind == "beacons" or launch is None):
                alternative = " or launch=(lat, lon)" if kind == "floats" else ""
                raise InputError(
                    f"rafostrack.track: arrivals given as a DataFrame need {kind}= (a DataFrame or a file "
                    f"with columns {expected}){alternative}"
                )
        float_id, arrivals = _frames_float_id(arrivals, floats, float_id)
    paths: dict[str, Path | None] = {}
    written: dict[str, tuple[str, pd.DataFrame]] = {}
    values = {**frames, "arrivals": arrivals}
    for kind, name in (("arrivals", f"{float_id}.csv"), ("beacons", "beacons.csv"), ("floats", "floats.csv")):
        value = values[kind]
        if isinstance(value, pd.DataFrame):
            _write_frame(value, tmp / name)
            paths[kind] = tmp / name
            written[str(tmp / name)] = (kind, value)
        else:
            paths[kind] = None if value is None else Path(value)
    return _FrameMission(paths, written)


def _frames_float_id(arrivals: pd.DataFrame, floats: Any, float_id: str | None) -> tuple[str, pd.DataFrame]:
    """The float that a DataFrame of arrivals belongs to, and its arrivals (module
    docstring): `float_id`, else the arrivals' `float_id` column, else the floats
    DataFrame's one row; without floats (a launch position) `float`."""
    table = isinstance(floats, pd.DataFrame) and "float_id" in floats.columns
    held = list(dict.fromkeys(floats["float_id"].astype(str))) if table else []
    if "float_id" in arrivals.columns:
        ids = arrivals["float_id"].astype(str)
        named = list(dict.fromkeys(ids))
        if float_id is None and len(named) > 1:
            raise InputError(
                f"rafostrack.track: the arrivals DataFrame holds the arrivals of {len(named)} floats "
                f"({listing(named)}); expected one float's: give float_id= one of them"
            )
        if float_id is None and named:
            float_id = named[0]
        if float_id is not None and str(float_id) not in named:
            raise InputError(
                f"rafostrack.track: float_id {float_id!r} is not in the arrivals DataFrame's float_id column"
                f"{nearest_id(str(float_id), named)}; it holds {listing(named) or 'no rows'}"
            )
        arrivals = arrivals[(ids == str(float_id)).to_numpy()].drop(columns="float_id")
    if float_id is None:
        if len(held) > 1:
            raise InputError(
                f"rafostrack.track: the floats DataFrame holds {len(held)} floats ({listing(held)}) and the "
                "arrivals DataFrame names none (no float_id column); expected one float's arrivals and which float "
                f"they are: give float_id= (e.g. float_id={held[0]!r}), or pass that float's row of the floats table"
            )
        if floats is not None and not isinstance(floats, pd.DataFrame):
            raise InputError(
                f"rafostrack.track: the arrivals DataFrame names no float (no float_id column); give float_id= "
                f"(a float_id of {floats})"
            )
        return (held[0] if held else "float"), arrivals
    if table and str(float_id) not in held:
        raise InputError(
            f"rafostrack.track: float_id {float_id!r} is not in the floats DataFrame{nearest_id(str(float_id), held)}; "
            f"it holds {listing(held) or 'no rows'}"
        )
    return str(float_id), arrivals


def _write_frame(frame: pd.DataFrame, path: Path) -> None:
    """`frame` as CSV: datetime columns as ISO-8601 UTC with a Z (a naive time is UTC), every
    other value as it is (text is checked by the reader as a file's would be)."""
    from .io.atomic import write_text_atomic

    frame = frame.copy()
    for col in frame.columns:
        if isinstance(frame[col].dtype, pd.DatetimeTZDtype) or pd.api.types.is_datetime64_dtype(frame[col]):
            frame[col] = _iso_utc(frame[col])
    write_text_atomic(path, frame.to_csv(index=False, lineterminator="\n"))


def _iso_utc(times: pd.Series) -> pd.Series:
    """Datetimes as ISO-8601 UTC text with a Z (seconds, or microseconds where any time has
    them); NaT stays missing."""
    if isinstance(times.dtype, pd.DatetimeTZDtype):
        times = times.dt.tz_convert("UTC").dt.tz_localize(None)
    fraction = bool(((times.dt.microsecond != 0) | (times.dt.nanosecond != 0)).any())
    return times.dt.strftime("%Y-%m-%dT%H:%M:%S.%f" if fraction else "%Y-%m-%dT%H:%M:%S") + "Z"


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
    track, labels, modes = (_utc(t) for t in (est.track, est.labels, est.modes))
    return TrackRun(loaded.problem.info.float_id, track, labels, modes, run, output, loaded.problem, out_dir)


def _utc(table: pd.DataFrame) -> pd.DataFrame:
    """`table` with its `time` column UTC (tz-aware), as the Parquet files hold it."""
    return table.assign(time=pd.to_datetime(table["time"]).dt.tz_localize("UTC"))
