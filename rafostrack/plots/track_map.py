"""`track.png`: the track on a map with uncertainty ellipses, modes, beacons, fixes and a scale bar.

The frame is fitted to the track, the launch and end fixes (and the truth, when drawn) plus a
margin, not to the beacon array: beacons outside it are marked on its edge, towards where
they are, and every beacon's name is written inside the map, off the title (`labels`).
Ticks read as degrees with hemisphere letters (105°W, 58°S). Map context (coastline, depth)
comes through one seam: `plot_track(..., background=...)` is called once with the frame
before anything else is drawn (`Background`); by default the coastline and, for a float
tracked with context constraints, its depth contours (`context_layer`).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from pathlib import Path
from typing import Any

import matplotlib
import matplotlib.dates as mdates
import numpy as np
import pandas as pd
from matplotlib import patheffects
from matplotlib.axes import Axes
from matplotlib.cm import ScalarMappable
from matplotlib.colors import Normalize
from matplotlib.figure import Figure
from matplotlib.layout_engine import ConstrainedLayoutEngine
from matplotlib.patches import Patch, Polygon
from matplotlib.ticker import FuncFormatter
from numpy.typing import NDArray

from ..domain import BeaconTable, FloatInfo
from ..summaries.posterior import ELLIPSE_95_SCALE
from .base import (
    DPI,
    FIGSIZE,
    KM_PER_DEG,
    SD_CIRCLES,
    TIME_CMAP,
    _column,
    _note,
    _reference_lon,
    _times,
    _unwrap_lon,
    date_ticks,
    figure,
    float_name,
    lat_text,
    lon_text,
    save_png,
)
from .context_layer import draw_context, float_context
from .labels import Label, draw_labels, marker_box

# Draws map context under the data: (axes, lat_min, lat_max, lon_min, lon_max), the frame in
# degrees as drawn (longitudes within 180° of the track's, so they may pass ±180 at the dateline).
Background = Callable[[Axes, float, float, float, float], None]

MARGIN_FRACTION = 0.15  # of the larger extent, on every side
MIN_MARGIN_KM = 10.0
MIN_HALF_KM = 25.0  # a frame at least 50 km across
MAX_FRAME_RATIO = 2.0  # width / height (km) kept within [1/2, 2]
MIN_ELLIPSE_PX = 12.0  # the median 95% ellipse is drawn at least this wide, enlarged if need be
ENLARGEMENTS = (1, 2, 5, 10, 20, 50, 100, 200, 500, 1000)
ELLIPSE_STYLE = {"face_alpha": 0.25, "edge_alpha": 0.9, "lw": 0.8}
LABEL_ZORDER = 10  # beacon labels above every data artist


def frame_of(lat: NDArray, lon: NDArray) -> tuple[float, float, float, float]:
    """(lat_min, lat_max, lon_min, lon_max) around the finite points: their extent plus
    `MARGIN_FRACTION` of the larger extent (at least `MIN_MARGIN_KM`) on every side, at least
    2 x `MIN_HALF_KM` across, the shorter side widened to keep width/height within `MAX_FRAME_RATIO`."""
    ok = np.isfinite(lat) & np.isfinite(lon)
    lat, lon = np.asarray(lat)[ok], np.asarray(lon)[ok]
    lat_c, lon_c = 0.5 * (lat.min() + lat.max()), 0.5 * (lon.min() + lon.max())
    coslat = max(np.cos(np.radians(lat_c)), 0.05)
    half_x = 0.5 * (lon.max() - lon.min()) * KM_PER_DEG * coslat
    half_y = 0.5 * (lat.max() - lat.min()) * KM_PER_DEG
    margin = max(MARGIN_FRACTION * 2 * max(half_x, half_y), MIN_MARGIN_KM)
    half_x, half_y = max(half_x + margin, MIN_HALF_KM), max(half_y + margin, MIN_HALF_KM)
    half_x, half_y = max(half_x, half_y / MAX_FRAME_RATIO), max(half_y, half_x / MAX_FRAME_RATIO)
    dlat, dlon = half_y / KM_PER_DEG, half_x / (KM_PER_DEG * coslat)
    return float(lat_c - dlat), float(lat_c + dlat), float(lon_c - dlon), float(lon_c + dlon)


def _sd_step_days(span_days: float) -> float:
    """A round spacing (days) giving about SD_CIRCLES uncertainty ellipses along the track."""
    for step in (1, 2, 5, 10, 15, 30, 60, 90, 180, 365):
        if span_days / step <= SD_CIRCLES:
            return float(step)
    return float(np.ceil(span_days / SD_CIRCLES))


def _sd_indices(times: NDArray[np.datetime64], step_days: float) -> NDArray[np.intp]:
    """Indices of the first track point at or after each multiple of `step_days`."""
    days = (times - times[0]) / np.timedelta64(1, "D")
    marks = np.arange(0.0, days[-1] + 1e-9, step_days)
    return np.unique(np.searchsorted(days, marks))


def _ellipse_polygon(lat: float, lon: float, smaj_km: float, smin_km: float, angle_deg: float) -> NDArray:
    """The 95% ellipse as (lon, lat) vertices: built in km, mapped to degrees locally."""
    phi = np.linspace(0.0, 2.0 * np.pi, 73)
    theta = np.radians(angle_deg)  # major axis, clockwise from north
    major, minor = np.array([np.sin(theta), np.cos(theta)]), np.array([np.cos(theta), -np.sin(theta)])
    pts = ELLIPSE_95_SCALE * (
        smaj_km * np.cos(phi)[:, None] * major[None, :] + smin_km * np.sin(phi)[:, None] * minor[None, :]
    )
    coslat = max(np.cos(np.radians(lat)), 0.05)
    return np.column_stack([lon + pts[:, 0] / (KM_PER_DEG * coslat), lat + pts[:, 1] / KM_PER_DEG])


def enlargement(major_95_km: NDArray, frame_width_km: float, width_px: float) -> int:
    """The smallest round factor (`ENLARGEMENTS`) drawing the median 95% ellipse at least
    `MIN_ELLIPSE_PX` wide on an axes `width_px` wide showing `frame_width_km`."""
    median_px = 2.0 * float(np.nanmedian(major_95_km)) * width_px / frame_width_km
    return next((f for f in ENLARGEMENTS if median_px * f >= MIN_ELLIPSE_PX), ENLARGEMENTS[-1])


def _draw_ellipses(ax: Axes, track: pd.DataFrame, times: NDArray, lat: NDArray, lon: NDArray, colors: NDArray,
                   frame_width_km: float) -> tuple[float, int] | None:  # fmt: skip
    """Draw the 95% ellipse every few days (a circle of radius 2.45 x sd_km/sqrt(2) when the
    track has no ellipse columns), enlarged by a round factor when too small to see; return
    (spacing in days, factor), or None if none was drawn."""
    sd = _column(track, "sd_km")
    if "smaj_km" in track:
        axes = np.column_stack([_column(track, "smaj_km"), _column(track, "smin_km"), _column(track, "angle_deg")])
    else:
        axes = np.column_stack([sd / np.sqrt(2.0), sd / np.sqrt(2.0), np.zeros_like(sd)])
    if len(times) == 0 or not np.isfinite(axes[:, 0]).any():
        return None
    step = _sd_step_days((times[-1] - times[0]) / np.timedelta64(1, "D"))
    chosen = [k for k in _sd_indices(times, step) if np.all(np.isfinite(axes[k])) and np.isfinite(lat[k] + lon[k])]
    if not chosen:
        return None
    width_px = FIGSIZE[0] * DPI * 0.7  # the map's share of the figure, roughly
    factor = enlargement(ELLIPSE_95_SCALE * axes[chosen, 0], frame_width_km, width_px)
    for k in chosen:
        vertices = _ellipse_polygon(lat[k], lon[k], factor * axes[k, 0], factor * axes[k, 1], axes[k, 2])
        ax.add_patch(Polygon(vertices, **_ellipse_colors(colors[k]), zorder=3.5))
    return step, factor


def _ellipse_colors(color: Any) -> dict[str, Any]:
    """Face and edge colours (and line width) of an ellipse, and of its legend patch."""
    rgb = tuple(color[:3])
    return {
        "fc": (*rgb, ELLIPSE_STYLE["face_alpha"]),
        "ec": (*rgb, ELLIPSE_STYLE["edge_alpha"]),
        "lw": ELLIPSE_STYLE["lw"],
    }


def _draw_modes(ax: Axes, track: pd.DataFrame, modes: pd.DataFrame | None, ref_lon: float) -> bool:
    """Ring the ambiguous positions and mark the second modes; True if any were drawn."""
    if "ambiguous" not in track or not track["ambiguous"].any():
        return False
    marks: list[tuple[pd.DataFrame, dict[str, Any], str]] = [
        (track[track["ambiguous"]], {"s": 40, "facecolors": "none", "edgecolors": "tab:red", "linewidths": 0.8},
         "ambiguous (reported mode)")
    ]  # fmt: skip
    if modes is not None and len(modes):
        marks.append(
            (modes[modes["mode"] == 2], {"s": 22, "marker": "x", "c": "tab:red", "linewidths": 0.9}, "second mode")
        )
    for frame, style, label in marks:
        ax.scatter(_unwrap_lon(frame["lon"].to_numpy(), ref_lon), frame["lat"], zorder=4.5, label=label, **style)
    return True


def _edge_point(lat: float, lon: float, frame: tuple[float, float, float, float]) -> tuple[float, float]:
    """Where the line from the frame's centre towards (lat, lon) leaves the frame."""
    lat0, lat1, lon0, lon1 = frame
    cy, cx = 0.5 * (lat0 + lat1), 0.5 * (lon0 + lon1)
    dy, dx = lat - cy, lon - cx
    scale = min((0.5 * (lat1 - lat0)) / abs(dy) if dy else np.inf, (0.5 * (lon1 - lon0)) / abs(dx) if dx else np.inf)
    return cy + 0.97 * scale * dy, cx + 0.97 * scale * dx


def _draw_beacons(ax: Axes, beacons: BeaconTable, frame: tuple[float, float, float, float]) -> list[Label]:
    """Beacons in the frame as black triangles, those outside as hollow ones on the frame's
    edge towards them; their names, to write once the layout is drawn (`labels.draw_labels`)."""
    lat0, lat1, lon0, lon1 = frame
    lon = _unwrap_lon(beacons.lon, 0.5 * (lon0 + lon1))
    inside = (beacons.lat >= lat0) & (beacons.lat <= lat1) & (lon >= lon0) & (lon <= lon1)
    if inside.any():
        ax.scatter(lon[inside], beacons.lat[inside], marker="^", s=70, c="k", edgecolors="w", linewidths=0.8,
                   zorder=5, label="beacon")  # fmt: skip
    edge = [_edge_point(beacons.lat[i], lon[i], frame) for i in np.flatnonzero(~inside)]
    if edge:
        ey, ex = np.array(edge).T
        ax.scatter(ex, ey, marker="^", s=50, facecolors="w", edgecolors="k", linewidths=0.9, zorder=5,
                   label="beacon outside the frame (on its edge, towards it)")  # fmt: skip
    points = [(b, x, y) for b, x, y in zip(beacons.beacon_id[inside], lon[inside], beacons.lat[inside], strict=True)]
    points += [(b, x, y) for b, (y, x) in zip(beacons.beacon_id[~inside], edge, strict=True)]
    style = {"zorder": LABEL_ZORDER, "bbox": {"boxstyle": "round,pad=0.15", "fc": "w", "ec": "none", "alpha": 0.8}}
    return [Label(str(b), float(x), float(y), 8.0, style, pad_pt=0.15 * 8.0) for b, x, y in points]


def _draw_fixes(ax: Axes, info: FloatInfo, ref_lon: float) -> None:
    """Launch fix (green circle) and, when known, end fix (red square)."""
    fixes = [(info.launch_lat, info.launch_lon, info.launch_time, "o", 10, "tab:green", "launch")]
    if info.has_end_fix:
        fixes.append((info.end_lat, info.end_lon, info.end_time, "s", 9, "tab:red", "end fix"))
    for lat, lon, when, marker, size, color, name in fixes:
        label = f"{name} {np.datetime_as_string(when, 'D')}"
        ax.plot(_unwrap_lon(lon, ref_lon), lat, marker, ms=size, mfc=color, mec="k", zorder=7, label=label)


def scale_bar_km(frame_width_km: float) -> float:
    """A round length (1, 2 or 5 x 10^k km) near a fifth of the frame's width."""
    target = frame_width_km / 5.0
    exponent = np.floor(np.log10(target))
    return float(max((m * 10**exponent for m in (1, 2, 5) if m * 10**exponent <= target), default=10**exponent))


def _draw_scale_bar(ax: Axes, frame: tuple[float, float, float, float]) -> None:
    """A bar of round length in km at the lower left of the frame, labelled above it."""
    lat0, lat1, lon0, lon1 = frame
    y = lat0 + 0.06 * (lat1 - lat0)
    coslat = max(np.cos(np.radians(y)), 0.05)
    km = scale_bar_km((lon1 - lon0) * KM_PER_DEG * coslat)
    x0 = lon0 + 0.05 * (lon1 - lon0)
    x1 = x0 + km / (KM_PER_DEG * coslat)
    halo = [patheffects.withStroke(linewidth=4, foreground="w")]
    ax.plot([x0, x1], [y, y], "-", color="k", lw=2.0, solid_capstyle="butt", zorder=8, gid="scalebar",
            path_effects=halo)  # fmt: skip
    ax.annotate(f"{km:g} km", (0.5 * (x0 + x1), y), xytext=(0, 4), textcoords="offset points", ha="center",
                va="bottom", fontsize=8, zorder=8, gid="scalebar", path_effects=halo)  # fmt: skip


def _time_norm(tnum: NDArray) -> Normalize:
    """Colour normalisation over the track's dates (a one-day span for a single time)."""
    lo, hi = float(tnum.min()), float(tnum.max())
    return Normalize(lo, hi) if hi > lo else Normalize(lo - 0.5, hi + 0.5)


def map_title(float_id: str) -> str:
    """'float767: estimated track' (an id already saying 'float' is not repeated), else
    'Float F01: estimated track'."""
    return f"{float_name(float_id)}: estimated track"


def plot_track(
    track: pd.DataFrame,
    beacons: BeaconTable,
    info: FloatInfo,
    path: Path,
    truth: pd.DataFrame | None = None,
    modes: pd.DataFrame | None = None,
    background: Background | None = None,
) -> Path:
    """`draw_track` into a new figure, written as a PNG to `path`."""
    with figure() as fig:
        draw_track(fig, track, beacons, info, truth, modes, background)
        return save_png(fig, path)


def draw_track(
    fig: Figure,
    track: pd.DataFrame,
    beacons: BeaconTable,
    info: FloatInfo,
    truth: pd.DataFrame | None = None,
    modes: pd.DataFrame | None = None,
    background: Background | None = None,
) -> Figure:
    """Map of the estimated track coloured by time, with 95% ellipses, ambiguous positions and
    their second modes, beacons, fixes, a scale bar and optional truth; `background` draws
    map context under it (module docstring)."""
    times = _times(track)
    lat, lon_raw = _column(track, "lat"), _column(track, "lon")
    ref_lon = _reference_lon(lon_raw, info.launch_lon)
    lon = _unwrap_lon(lon_raw, ref_lon)
    frame = _map_frame(lat, lon, info, truth, ref_lon)
    ax, frame_width_km = _map_axes(fig, frame, info, background)
    handles: list[object] = []
    if len(times):
        handles = _draw_estimate(fig, ax, track, times, lat, lon, modes, ref_lon, frame_width_km)
    else:
        _note(ax, "no track estimate")
    if truth is not None and len(truth):
        tlon = _unwrap_lon(_column(truth, "lon"), ref_lon)
        ax.plot(tlon, _column(truth, "lat"), "--", color="k", lw=1.2, zorder=4, label="truth")
    names = _draw_beacons(ax, beacons, frame)
    _draw_fixes(ax, info, ref_lon)
    _draw_scale_bar(ax, frame)
    _finish_map(fig, ax, frame, handles, map_title(info.float_id) + _span_text(times))
    draw_labels(ax, names, [marker_box(ax, n.x, n.y) for n in names])
    return fig


def _map_frame(
    lat: NDArray, lon: NDArray, info: FloatInfo, truth: pd.DataFrame | None, ref_lon: float
) -> tuple[float, float, float, float]:
    """The map's (lat0, lat1, lon0, lon1) about the track, the fixes and the truth
    (longitudes unwrapped about `ref_lon`)."""
    pts_lat: list[NDArray] = [lat, np.array([info.launch_lat])]
    pts_lon: list[NDArray] = [lon, _unwrap_lon(np.array([info.launch_lon]), ref_lon)]
    if info.has_end_fix:
        pts_lat.append(np.array([info.end_lat]))
        pts_lon.append(_unwrap_lon(np.array([info.end_lon]), ref_lon))
    if truth is not None and len(truth):
        pts_lat.append(_column(truth, "lat"))
        pts_lon.append(_unwrap_lon(_column(truth, "lon"), ref_lon))
    return frame_of(np.concatenate(pts_lat), np.concatenate(pts_lon))


def _map_axes(
    fig: Figure, frame: tuple[float, float, float, float], info: FloatInfo, background: Background | None
) -> tuple[Axes, float]:
    """The map's axes over `frame` (aspect 1 / cos(mid latitude)) with the background drawn,
    and the frame's width in km."""
    lat0, lat1, lon0, lon1 = frame
    coslat = max(np.cos(np.radians(0.5 * (lat0 + lat1))), 0.05)
    ax = fig.add_subplot()
    ax.set_xlim(lon0, lon1)
    ax.set_ylim(lat0, lat1)
    ax.set_aspect(1.0 / coslat, adjustable="box")
    if background is None:  # the coastline, and the float's context grid if it has one
        background = functools.partial(draw_context, context=float_context(info.float_id))
    background(ax, lat0, lat1, lon0, lon1)  # the one seam for map context (coastline, depth)
    ax.set_xlim(lon0, lon1)
    ax.set_ylim(lat0, lat1)
    return ax, (lon1 - lon0) * KM_PER_DEG * coslat


def _draw_estimate(
    fig: Figure,
    ax: Axes,
    track: pd.DataFrame,
    times: NDArray[np.datetime64],
    lat: NDArray,
    lon: NDArray,
    modes: pd.DataFrame | None,
    ref_lon: float,
    frame_width_km: float,
) -> list[object]:
    """The estimated track coloured by time, its ellipses, second modes and time colour bar;
    the legend handles it adds beyond the axes' own."""
    handles: list[object] = []
    tnum = mdates.date2num(times)
    norm = _time_norm(tnum)
    cmap = matplotlib.colormaps[TIME_CMAP]
    colors = cmap(norm(tnum))
    ax.plot(lon, lat, "-", color="0.55", lw=0.8, zorder=2)
    ax.scatter(lon, lat, c=colors, s=10, zorder=3, label="estimated track")
    drawn = _draw_ellipses(ax, track, times, lat, lon, colors, frame_width_km)
    if drawn is not None:
        step, factor = drawn
        size = "" if factor == 1 else f", drawn ×{factor} enlarged"
        handles.append(Patch(**_ellipse_colors(cmap(0.5)), label=f"95% ellipse (every {step:g} d{size})"))
    _draw_modes(ax, track, modes, ref_lon)
    if float(norm.vmax or 0.0) - float(norm.vmin or 0.0) > 1.0:  # a colour scale means nothing for one window
        cbar = fig.colorbar(ScalarMappable(norm, cmap), ax=ax, shrink=0.9, pad=0.01)
        date_ticks(cbar.ax.yaxis, times.min(), times.max())
    return handles


def _finish_map(
    fig: Figure, ax: Axes, frame: tuple[float, float, float, float], handles: list[object], title: str
) -> None:
    """Limits, degree labels, grid, the legend under the map and the title."""
    lat0, lat1, lon0, lon1 = frame
    ax.set_xlim(lon0, lon1)
    ax.set_ylim(lat0, lat1)
    ax.xaxis.set_major_formatter(FuncFormatter(lon_text))
    ax.yaxis.set_major_formatter(FuncFormatter(lat_text))
    ax.set_xlabel("longitude")
    ax.set_ylabel("latitude")
    ax.grid(True, lw=0.4, alpha=0.5)
    legend_handles, _ = ax.get_legend_handles_labels()
    all_handles = legend_handles + handles
    fig.legend(handles=all_handles, loc="outside lower center", fontsize=8, frameon=False,
               ncols=min(len(all_handles), 4))  # fmt: skip
    ax.set_title(title)
    _keep_title_inside(fig, ax)


def _keep_title_inside(fig: Figure, ax: Axes) -> None:
    """Lower the layout's top until the title is inside the figure: with the map's fixed
    aspect, constrained layout can place the axes so high that the title is cut off."""
    renderer = fig.canvas.get_renderer()  # type: ignore[attr-defined]  # Agg canvases have one
    fig.canvas.draw()
    overflow = ax.title.get_window_extent(renderer).y1 - fig.bbox.height
    engine = fig.get_layout_engine()
    if overflow > 0 and isinstance(engine, ConstrainedLayoutEngine):
        engine.set(rect=(0.0, 0.0, 1.0, 1.0 - (overflow + 4.0) / fig.bbox.height))
        fig.canvas.draw()  # the layout the names are then placed in (`labels.draw_labels`)


def _span_text(times: NDArray[np.datetime64]) -> str:
    """' (first – last, n windows)' for a title, or '' when empty."""
    if not len(times):
        return ""
    first = np.datetime_as_string(times.min(), "D")
    last = np.datetime_as_string(times.max(), "D")
    plural = "" if len(times) == 1 else "s"
    return f" ({first} – {last}, {len(times)} window{plural})"
