"""`overview.png`: every float's track of an output tree on one map, coloured by whether the
float needs a look, with the beacons.

The frame is fitted to the tracks and the beacons (`track_map.frame_of`); longitudes are
unwrapped about the tracks' circular mean, so a mission across the dateline stays in one
piece. The floats that need a look are drawn last (on top), in a strong colour, each named
at its last position; the others are thin and muted, named only when there are few floats
(`LABEL_ALL_MAX`). The coastline comes through the same seam as on `track.png`
(`track_map.Background`, by default `context_layer.draw_context`).
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

from .base import KM_PER_DEG, _note, _reference_lon, _unwrap_lon, figure, lat_text, lon_text, save_png
from .context_layer import draw_context
from .track_map import Background, _keep_title_inside, _label_place, frame_of

NEEDS_LOOK = "needs a look"
OK = "ok"
# Colour and line width per status; the order is the drawing order (the last on top).
STATUS_STYLE: dict[str, dict[str, Any]] = {
    OK: {"color": "#1580bf", "lw": 0.9, "alpha": 0.6},
    NEEDS_LOOK: {"color": "#d62728", "lw": 1.6, "alpha": 0.95},
}
OTHER_STYLE: dict[str, Any] = {"color": "0.3", "lw": 1.0, "alpha": 0.8}  # a status not in STATUS_STYLE
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
    """The tracks coloured by status, their starts as dots, the floats' names (module
    docstring) and the beacons (`beacon_id, lat, lon` rows) as black triangles."""
    layout = _layout(paths, beacons)
    ax = fig.add_subplot()
    if layout.frame is None:
        _note(ax, "no track to draw")
        ax.set_title(title)
        return fig
    _map_axes(ax, layout.frame, background)
    named = len(layout.paths) <= LABEL_ALL_MAX
    order = [*STATUS_STYLE, *sorted({p.status for p in layout.paths} - set(STATUS_STYLE))]
    placed: list[tuple[float, float]] = []
    for status in order:
        for p in (p for p in layout.paths if p.status == status):
            _draw_path(ax, p, layout, placed, label=named or status != OK)
    if layout.beacons is not None and len(layout.beacons):
        _draw_beacons(ax, layout.beacons)
    _legend(fig, layout)
    ax.set_title(title)
    _keep_title_inside(fig, ax)
    return fig


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


def _draw_path(ax: Axes, p: FloatPath, layout: _Layout, placed: list[tuple[float, float]], label: bool) -> None:
    """One track in its status's style, a dot at its first position, its name by its last
    (where it overlaps no name already `placed`, `track_map._label_place`)."""
    style = STATUS_STYLE.get(p.status, OTHER_STYLE)
    ok = np.isfinite(p.lat) & np.isfinite(p.lon)
    lat, lon = p.lat[ok], _unwrap_lon(p.lon[ok], layout.ref_lon)
    zorder = 3 if p.status == OK else 4
    ax.plot(lon, lat, "-", color=style["color"], lw=style["lw"], alpha=style["alpha"], zorder=zorder)
    ax.plot(lon[:1], lat[:1], "o", ms=3.5, color=style["color"], zorder=zorder)
    if not label or layout.frame is None:
        return
    lat0, lat1, lon0, lon1 = layout.frame
    fx, fy = (lon[-1] - lon0) / (lon1 - lon0), (lat[-1] - lat0) / (lat1 - lat0)
    (dx, dy), offset, ha, va = _label_place(fx, fy, placed)
    placed.append((fx + dx, fy + dy))
    halo = [patheffects.withStroke(linewidth=2.5, foreground="w")]
    ax.annotate(p.name, (lon[-1], lat[-1]), xytext=offset, textcoords="offset points", ha=ha, va=va, fontsize=7,
                color=style["color"], zorder=9, path_effects=halo, annotation_clip=True)  # fmt: skip


def _draw_beacons(ax: Axes, beacons: pd.DataFrame) -> None:
    """Black triangles, each named below it in grey."""
    ax.scatter(beacons["lon"], beacons["lat"], marker="^", s=45, c="k", edgecolors="w", linewidths=0.7, zorder=5)
    for b, x, y in zip(beacons["beacon_id"], beacons["lon"], beacons["lat"], strict=True):
        ax.annotate(str(b), (x, y), xytext=(0, -8), textcoords="offset points", ha="center", va="top",
                    fontsize=6, color="0.3", zorder=5, annotation_clip=True)  # fmt: skip


def _legend(fig: Figure, layout: _Layout) -> None:
    """One entry per status drawn, with its count; the start dot; the beacons."""
    handles = []
    for status in [*STATUS_STYLE, *sorted({p.status for p in layout.paths} - set(STATUS_STYLE))]:
        n = sum(p.status == status for p in layout.paths)
        if n:
            color = STATUS_STYLE.get(status, OTHER_STYLE)["color"]
            handles.append(Line2D([], [], color=color, lw=2.0, label=f"{status} ({n})"))
    handles.append(Line2D([], [], ls="none", marker="o", ms=4, color="0.3", label="first position"))
    if layout.beacons is not None and len(layout.beacons):
        handles.append(Line2D([], [], ls="none", marker="^", ms=7, color="k", label="beacon"))
    fig.legend(handles=handles, loc="outside lower center", ncols=len(handles), fontsize=9, frameon=False)
