"""`arrivals.png`: stored TOAs against time coloured by label, with each beacon's predicted
arrival along the track (the paper's Figure 1, labelled)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib.dates as mdates
import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from numpy.typing import NDArray

from ..config import ModelConfig
from ..domain import BeaconTable, FloatInfo
from ..model.measurement import predicted_arrivals
from .base import (
    CLUTTER_COLOR,
    TIME_LABEL,
    Color,
    _alpha,
    _column,
    _note,
    _rgba,
    _times,
    beacon_colors,
    date_axis,
    figure,
    float_name,
    save_png,
)


def _label_ids(labels: pd.DataFrame) -> NDArray[np.object_]:
    """Beacon id per label row as str, None for clutter (None, NaN or empty)."""
    if "beacon_id" not in labels.columns:
        return np.full(len(labels), None, dtype=object)
    raw = labels["beacon_id"]
    clutter = raw.isna() | (raw.astype(str).str.strip() == "")
    return np.asarray(np.where(clutter, None, raw.astype(str)), dtype=object)


def _predicted(
    track: pd.DataFrame, beacons: BeaconTable, info: FloatInfo, model: ModelConfig
) -> tuple[NDArray[np.datetime64], NDArray[np.float64]]:
    """Track times and each beacon's predicted TOA along the track, shape (n, n_beacons)."""
    times = _times(track)
    if not len(times):
        return times, np.full((0, len(beacons)), np.nan)
    pred = predicted_arrivals(times, _column(track, "lat"), _column(track, "lon"), beacons, info, model)
    return times, pred


def plot_arrivals(
    labels: pd.DataFrame,
    track: pd.DataFrame,
    beacons: BeaconTable,
    info: FloatInfo,
    model: ModelConfig,
    path: Path,
) -> Path:
    """`draw_arrivals` into a new figure, written as a PNG to `path`."""
    with figure() as fig:
        draw_arrivals(fig, labels, track, beacons, info, model)
        return save_png(fig, path)


def draw_arrivals(
    fig: Figure, labels: pd.DataFrame, track: pd.DataFrame, beacons: BeaconTable, info: FloatInfo, model: ModelConfig
) -> Figure:
    """Stored TOAs against time coloured by assigned beacon, with predicted arrival curves."""
    ids = [str(b) for b in beacons.beacon_id]
    label_ids = _label_ids(labels)
    extra = sorted({b for b in label_ids if b is not None} - set(ids))  # ids unknown to the table
    colors = beacon_colors(ids + extra)
    ltimes, toa, prob = _times(labels), _column(labels, "toa_s"), _column(labels, "prob")
    clutter = np.array([b is None for b in label_ids], dtype=bool)
    counts = pd.Series(label_ids[~clutter]).value_counts().to_dict()
    ptimes, pred = _predicted(track, beacons, info, model)
    shown = [k for k, b in enumerate(ids) if counts.get(b, 0) > 0]  # a beacon never heard: no curve, no entry
    ax = fig.add_subplot()
    handles: list[Line2D] = []
    marker = "_" if len(ptimes) == 1 else ""  # a one-point curve is drawn as a tick
    for k in shown:
        b = ids[k]
        ax.plot(ptimes, pred[:, k], "-", marker=marker, ms=12, color=colors[b], lw=1.0, alpha=0.8, zorder=2)
        handles.append(_scatter_beacon(ax, ltimes, toa, prob, label_ids == b, colors[b], b))
    for b in extra:
        handles.append(_scatter_beacon(ax, ltimes, toa, prob, label_ids == b, colors[b], b))
    if clutter.any():
        handles.append(_scatter_clutter(ax, ltimes[clutter], toa[clutter], prob[clutter]))
    if shown:
        handles.append(Line2D([], [], color="k", lw=1.0, label="predicted TOA\n(estimated track)"))
    if not len(labels):
        _note(ax, "no arrival times stored")
    _arrivals_axes(ax, info, ltimes, ptimes)
    ax.set_title(_arrivals_title(info, label_ids))
    if handles:
        _arrivals_legend(fig, handles, [b for b in ids if counts.get(b, 0) == 0])
    return fig


def _arrivals_legend(fig: Figure, handles: list[Line2D], unheard: Sequence[str]) -> None:
    """Legend of beacons (with TOA counts), clutter and predicted curves, right of the axes;
    its title names the beacons `unheard` (up to 4, else counts them)."""
    title = "beacon (n TOAs)"
    if unheard:
        title += "\nnot heard: " + (", ".join(unheard) if len(unheard) <= 4 else f"{len(unheard)} beacons")
    fig.legend(
        handles=handles,
        loc="outside right upper",
        fontsize=8,
        title=title,
        title_fontsize=8,
        ncols=1 if len(handles) <= 22 else 2,
        frameon=False,
    )


def _scatter_beacon(
    ax: Axes, times: NDArray, toa: NDArray, prob: NDArray, mask: NDArray[np.bool_], color: Color, name: str
) -> Line2D:
    """Scatter one beacon's labelled TOAs (opacity = label probability); return a legend proxy."""
    if mask.any():
        ax.scatter(times[mask], toa[mask], s=14, c=_rgba(color, _alpha(prob[mask])), linewidths=0, zorder=4)
    return Line2D([], [], color=color, marker="o", ms=5, lw=1.0, label=f"{name} ({int(mask.sum())})")


def _scatter_clutter(ax: Axes, times: NDArray, toa: NDArray, prob: NDArray) -> Line2D:
    """Scatter clutter TOAs as small grey crosses (opacity = probability); return a legend proxy."""
    rgba = _rgba(CLUTTER_COLOR, _alpha(prob))
    ax.scatter(times, toa, marker="x", s=12, linewidths=0.8, c=rgba, zorder=3)
    return Line2D([], [], ls="none", marker="x", color=CLUTTER_COLOR, label=f"clutter ({len(toa)})")


def _arrivals_axes(ax: Axes, info: FloatInfo, ltimes: NDArray, ptimes: NDArray) -> None:
    """Window-length y range, date x axis and labels for the arrivals plot."""
    ax.set_ylim(0.0, info.window_s)
    ax.set_ylabel("arrival time in window (s)")
    ax.grid(True, lw=0.4, alpha=0.5)
    times = np.concatenate([ltimes, ptimes])
    if len(times):
        lo, hi = times.min(), times.max()
        pad = max((hi - lo) * 0.02, np.timedelta64(12, "h"))
        ax.set_xlim(lo - pad, hi + pad)
    else:  # nothing to place in time: show the float's deployment
        end = info.end_time if info.has_end_fix else info.launch_time + np.timedelta64(1, "D")
        ax.set_xlim(mdates.date2num(info.launch_time), mdates.date2num(end))
    date_axis(ax.xaxis, TIME_LABEL)


def _arrivals_title(info: FloatInfo, label_ids: NDArray[np.object_]) -> str:
    """Title with the float id and TOA counts."""
    n = len(label_ids)
    n_clutter = int(sum(b is None for b in label_ids))
    return (
        f"{float_name(info.float_id)}: {n} stored TOAs, {n - n_clutter} assigned to beacons, {n_clutter} clutter"
        "\n(marker opacity = label probability; lines = predicted arrivals along the estimated track)"
    )
