"""An arrival record from per-TOA arrays, for readers of formats other than CSV.

`build_record` applies the checks `csv_mission.read_arrivals` applies to a CSV file (windows
before the launch are an error; TOAs outside [0, window_s] are dropped and windows holding
more than `max_signals` TOAs keep the earliest, each with a warning), naming the file and,
instead of a line, the record index (`where(i)`).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..domain import ArrivalRecord, FloatInfo, Window
from ..errors import InputError, Warnings
from .csv_table import time_text


def check_after_launch(
    path: Path, info: FloatInfo, times: NDArray[np.datetime64], where: Callable[[int], str], field: str = ""
) -> None:
    """InputError naming the earliest window when it is before the float's launch (`where(i)`
    names entry i: a line, a record; `field` is put before what was expected)."""
    first = int(np.argmin(times))
    if times[first] < info.launch_time:
        raise InputError(
            f"{path}: {where(first)}: window at {time_text(times[first])} is before the float's launch_time "
            f"{time_text(info.launch_time)}; {field}expected windows at or after the launch (check launch_time in "
            "floats.csv)"
        )


def build_record(
    path: Path,
    info: FloatInfo,
    times: NDArray[np.datetime64],
    toa_s: NDArray[np.float64],
    warnings: Warnings,
    *,
    labels: NDArray[np.object_] | None = None,
    quality: NDArray[np.float64] | None = None,
    where: Callable[[int], str] = lambda i: f"record {i + 1}",
) -> ArrivalRecord:
    """Windows of ascending TOAs from one entry per TOA: its window's opening time and the
    TOA (NaN = a window that stored nothing), with optional labels and correlation heights."""
    times = np.asarray(times, dtype="datetime64[ns]")
    toa = np.asarray(toa_s, dtype=float)
    if not len(times):
        raise InputError(f"{path}: no listening windows in the file; expected at least one")
    if np.isnat(times).any():
        raise InputError(f"{path}: {where(int(np.argmax(np.isnat(times))))}: window time missing; expected a time")
    check_after_launch(path, info, times, where)
    has = np.isfinite(toa)
    outside = has & ((toa < 0) | (toa > info.window_s))
    if outside.any():
        i = int(np.argmax(outside))
        warnings.add(
            f"{path}: {int(outside.sum())} TOA(s) outside the window [0, {info.window_s:g}] s dropped "
            f"(first at {where(i)}: {toa[i]:g})"
        )
    keep = has & ~outside
    windows: list[Window] = []
    truncated = 0
    for t in np.unique(times):
        idx = np.flatnonzero((times == t) & keep)
        idx = idx[np.argsort(toa[idx], kind="stable")]
        if len(idx) > info.max_signals:
            truncated += 1
            idx = idx[: info.max_signals]
        windows.append(
            Window(
                time=t,
                toa_s=toa[idx].copy(),
                beacon_id=None if labels is None else tuple(labels[idx]),
                quality=None if quality is None else np.asarray(quality, dtype=float)[idx].copy(),
            )
        )
    if truncated:
        warnings.add(
            f"{path}: {truncated} window(s) held more than max_signals={info.max_signals} TOAs; kept the earliest"
        )
    return ArrivalRecord(float_id=info.float_id, path=Path(path), windows=tuple(windows))
