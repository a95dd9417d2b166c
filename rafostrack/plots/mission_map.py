"""`overview.png`: every float's track of an output tree on one map, each in its own colour,
its line style saying whether the float needs a look, with the beacons.

The frame is fitted to the tracks and the beacons (`track_map.frame_of`); longitudes are
unwrapped about the tracks' circular mean, so a mission across the dateline stays in one
piece. Each float has its own colour (the qualitative `base.BEACON_PALETTE`, cycling beyond
20 floats), so tangled tracks can be told apart. The floats that need a look are drawn
last (on top), dashed and thicker, a cross at their last position, each named there; the
others are solid, named only when there are few floats (`LABEL_ALL_MAX`). The names are
placed once the layout is drawn, clear of the beacons and their names (`labels`). The
coastline comes through the same seam as on `track.png` (`track_map.Background`, by
default `context_layer.draw_context`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from matplotlib import patheffects
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.ticker import FuncFormatter
from numpy.typing import NDArray

from .base import (
    KM_PER_DEG,
    Color,
    _note,
    _reference_lon,
    _unwrap_lon,
    beacon_colors,
    figure,
    lat_text,
    lon_text,
    save_png,
)
from .context_layer import draw_context
from .labels import Label, draw_labels, marker_box
from .track_map import Background, _keep_title_inside, frame_of

NEEDS_LOOK = "needs a look"
OK = "ok"
# Line style, width and end marker per status (the colour is the float's own); the order
# is the drawing order (the last on top).
STATUS_STYLE: dict[str, dict[str, Any]] = {
    OK: {"ls": "-", "lw": 1.2, "alpha": 0.85, "end": None},
    NEEDS_LOOK: {"ls": "--", "lw": 1.9, "alpha": 1.0, "end": "X"},
}
OTHER_STYLE: dict[str, Any] = {"ls": ":", "lw": 1.4, "alpha": 0.9, "end": None}  # a status not in STATUS_STYLE
LABEL_ALL_MAX = 25  # up to this many floats, every track is named; beyond, those needing a look
MAP_WIDTH = 11.0  # inches
MAP_HEIGHTS = (4.5, 11.0)  # the least and the most, inches

Frame = tuple[float, float, float, float]  # lat0, lat1, lon0, lon1 (degrees, as drawn)


@dataclass(frozen=True)
class FloatPath:
    """One float's track as drawn: its name, positions (degrees) and status (a key of
    `STATUS_STYLE`)."""

    name: str
    lat: NDArray[np.float64] = field(repr=False)
    lon: NDArray[np.float64] = field(repr=False)
    status: str = OK


def plot_mission_map(
    paths: Sequence[FloatPath],
    beacons: pd.DataFrame | None,
    path: Path,
    title: str,
    background: Background | None = None,
) -> Path:
    """`draw_mission_map` into a new figure as tall as the frame needs, written as a PNG to
    `path` (atomically)."""
    with figure(*map_size(paths, beacons)) as fig:
        draw_mission_map(fig, paths, beacons, title, background)
        return save_png(fig, path)


@dataclass(frozen=True)
class _Layout:
    """What the map shows: the tracks with positions, the beacons and the frame, longitudes
    unwrapped about `ref_lon`."""

    paths: list[FloatPath]
    beacons: pd.DataFrame | None
    ref_lon: float
    frame: Frame | None  # None when no track has a position


def _layout(paths: Sequence[FloatPath], beacons: pd.DataFrame | None) -> _Layout:
    drawn = [p for p in paths if (np.isfinite(p.lat) & np.isfinite(p.lon)).any()]
    ref_lon = _reference_lon(np.concatenate([p.lon for p in drawn]) if drawn else np.zeros(0), 0.0)
    near = _beacons_near(beacons, ref_lon)
    return _Layout(drawn, near, ref_lon, _frame(drawn, near, ref_lon) if drawn else None)


def map_size(paths: Sequence[FloatPath], beacons: pd.DataFrame | None) -> tuple[float, float]:
    """(width, height) in inches: `MAP_WIDTH`, and a height giving the frame's shape (km) to
    the map with room for the title and the legend, within `MAP_HEIGHTS`."""
    frame = _layout(paths, beacons).frame
    if frame is None:
        return MAP_WIDTH, MAP_HEIGHTS[0]
    lat0, lat1, lon0, lon1 = frame
    coslat = max(np.cos(np.radians(0.5 * (lat0 + lat1))), 0.05)
    shape = (lat1 - lat0) / ((lon1 - lon0) * coslat)
    return MAP_WIDTH, float(np.clip(0.85 * MAP_WIDTH * shape + 1.5, *MAP_HEIGHTS))


def draw_mission_map(
    fig: Figure,
    paths: Sequence[FloatPath],
    beacons: pd.DataFrame | None,
    title: str,
    background: Background | None = None,
) -> Figure:
    """The tracks each in its own colour, styled by status, their starts as dots, the floats'
    names (module docstring) and the beacons (`beacon_id, lat, lon` rows) as black triangles."""
    layout = _layout(paths, beacons)
    ax = fig.add_subplot()
    if layout.frame is None:
        _note(ax, "no track to draw")
        ax.set_title(title)
        return fig
    _map_axes(ax, layout.frame, background)
    named = len(layout.paths) <= LABEL_ALL_MAX
    colors = beacon_colors([str(k) for k in range(len(layout.paths))])  # one per float, in order
    names: list[Label] = []
    for status in _statuses(layout):
        for k, p in enumerate(layout.paths):
            if p.status == status:
                names += _draw_path(ax, p, layout.ref_lon, colors[str(k)], label=named or status != OK)
    marks: list[Label] = []
    if layout.beacons is not None and len(layout.beacons):
        marks = _draw_beacons(ax, layout.beacons)
    _legend(fig, layout)
    ax.set_title(title)
    _keep_title_inside(fig, ax)
    draw_labels(ax, [*marks, *names], [marker_box(ax, m.x, m.y) for m in [*marks, *names]])
    return fig


def _statuses(layout: _Layout) -> list[str]:
    """The statuses drawn, in drawing order: `STATUS_STYLE`'s, then any other alphabetically."""
    return [*STATUS_STYLE, *sorted({p.status for p in layout.paths} - set(STATUS_STYLE))]


def _beacons_near(beacons: pd.DataFrame | None, ref_lon: float) -> pd.DataFrame | None:
    """The beacons with finite positions, longitudes unwrapped about `ref_lon`."""
    if beacons is None or not len(beacons):
        return None
    lat = pd.to_numeric(beacons["lat"], errors="coerce").to_numpy(dtype=float)
    lon = pd.to_numeric(beacons["lon"], errors="coerce").to_numpy(dtype=float)
    ok = np.isfinite(lat) & np.isfinite(lon)
    return pd.DataFrame({"beacon_id": beacons["beacon_id"].astype(str).to_numpy()[ok], "lat": lat[ok],
                         "lon": _unwrap_lon(lon[ok], ref_lon)})  # fmt: skip


def _frame(paths: Sequence[FloatPath], beacons: pd.DataFrame | None, ref_lon: float) -> Frame:
    """(lat0, lat1, lon0, lon1) about every track and beacon."""
    lat = [p.lat for p in paths]
    lon = [_unwrap_lon(p.lon, ref_lon) for p in paths]
    if beacons is not None and len(beacons):
        lat.append(beacons["lat"].to_numpy(dtype=float))
        lon.append(beacons["lon"].to_numpy(dtype=float))
    return frame_of(np.concatenate(lat), np.concatenate(lon))


def _map_axes(ax: Axes, frame: Frame, background: Background | None) -> None:
    """Limits, aspect 1 / cos(mid latitude), the coastline (or `background`), degree ticks."""
    lat0, lat1, lon0, lon1 = frame
    coslat = max(np.cos(np.radians(0.5 * (lat0 + lat1))), 0.05)
    ax.set_xlim(lon0, lon1)
    ax.set_ylim(lat0, lat1)
    ax.set_aspect(1.0 / coslat, adjustable="box")
    (background or draw_context)(ax, lat0, lat1, lon0, lon1)
    ax.set_xlim(lon0, lon1)
    ax.set_ylim(lat0, lat1)
    ax.xaxis.set_major_formatter(FuncFormatter(lon_text))
    ax.yaxis.set_major_formatter(FuncFormatter(lat_text))
    ax.set_xlabel(f"longitude (frame {(lon1 - lon0) * KM_PER_DEG * coslat:,.0f} km wide)")
    ax.set_ylabel("latitude")
    ax.grid(True, lw=0.4, alpha=0.5)


def _draw_path(ax: Axes, p: FloatPath, ref_lon: float, color: Color, label: bool) -> list[Label]:
    """One track in its colour and its status's style, a dot at its first position (and the
    status's mark at its last); its name to write by its last position, when `label`."""
    style = STATUS_STYLE.get(p.status, OTHER_STYLE)
    ok = np.isfinite(p.lat) & np.isfinite(p.lon)
    lat, lon = p.lat[ok], _unwrap_lon(p.lon[ok], ref_lon)
    zorder = 3 if p.status == OK else 4
    ax.plot(lon, lat, color=color, ls=style["ls"], lw=style["lw"], alpha=style["alpha"], zorder=zorder)
    ax.plot(lon[:1], lat[:1], "o", ms=3.5, color=color, zorder=zorder)
    if style["end"]:
        ax.plot(lon[-1:], lat[-1:], style["end"], ms=7, mfc=color, mec="k", mew=0.6, zorder=zorder)
    if not label:
        return []
    halo = [patheffects.withStroke(linewidth=2.5, foreground="w")]
    weight = "normal" if p.status == OK else "bold"
    text_style = {"color": color, "zorder": 9, "path_effects": halo, "fontweight": weight}
    return [Label(p.name, float(lon[-1]), float(lat[-1]), 7.0, text_style)]


def _draw_beacons(ax: Axes, beacons: pd.DataFrame) -> list[Label]:
    """Black triangles; their names, to write once the layout is drawn (grey, beside each)."""
    ax.scatter(beacons["lon"], beacons["lat"], marker="^", s=45, c="k", edgecolors="w", linewidths=0.7, zorder=5)
    style = {"color": "0.3", "zorder": 5}
    return [
        Label(str(b), float(x), float(y), 6.0, style)
        for b, x, y in zip(beacons["beacon_id"], beacons["lon"], beacons["lat"], strict=True)
    ]


def _legend(fig: Figure, layout: _Layout) -> None:
    """One entry per status drawn (its line style and mark, in black), with its count; the
    start dot; the beacons."""
    handles = []
    for status in _statuses(layout):
        n = sum(p.status == status for p in layout.paths)
        if n:
            style = STATUS_STYLE.get(status, OTHER_STYLE)
            handles.append(Line2D([], [], color="k", ls=style["ls"], lw=style["lw"], marker=style["end"] or "",
                                  ms=7, mfc="0.6", mec="k", mew=0.6, label=f"{status} ({n})"))  # fmt: skip
    handles.append(Line2D([], [], ls="none", marker="o", ms=4, color="0.3", label="first position"))
    if layout.beacons is not None and len(layout.beacons):
        handles.append(Line2D([], [], ls="none", marker="^", ms=7, color="k", label="beacon"))
    fig.legend(handles=handles, loc="outside lower center", ncols=len(handles), fontsize=9, frameon=False)
