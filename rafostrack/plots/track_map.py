"""`track.png`: the track on a map with uncertainty ellipses, modes, beacons and fixes."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib
import matplotlib.dates as mdates
import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.cm import ScalarMappable
from matplotlib.colors import Normalize
from matplotlib.lines import Line2D
from matplotlib.patches import Patch, Polygon
from numpy.typing import NDArray

from ..domain import BeaconTable, FloatInfo
from ..posterior import ELLIPSE_95_SCALE
from .base import (
    KM_PER_DEG,
    MAX_BEACONS_ALL,
    SD_CIRCLES,
    TIME_CMAP,
    _column,
    _note,
    _reference_lon,
    _times,
    _unwrap_lon,
    date_axis,
    figure,
    save_png,
)
from .context_layer import draw_context, float_context


def _select_beacons(beacons: BeaconTable, lat: NDArray, lon: NDArray, margin_km: float = 600.0) -> NDArray[np.bool_]:
    """Beacons to draw: all if few, else those within a margin (km) of the points' extent."""
    if len(beacons) <= MAX_BEACONS_ALL or not np.isfinite(lat).any():
        return np.ones(len(beacons), dtype=bool)
    lat0, lat1 = np.nanmin(lat), np.nanmax(lat)
    lon0, lon1 = np.nanmin(lon), np.nanmax(lon)
    coslat = max(np.cos(np.radians(0.5 * (lat0 + lat1))), 0.05)
    extent_km = max(lat1 - lat0, (lon1 - lon0) * coslat) * KM_PER_DEG
    margin = max(margin_km, 0.5 * extent_km) / KM_PER_DEG  # degrees of latitude
    blon = _unwrap_lon(beacons.lon, 0.5 * (lon0 + lon1))
    inside = (beacons.lat >= lat0 - margin) & (beacons.lat <= lat1 + margin)
    return inside & (blon >= lon0 - margin / coslat) & (blon <= lon1 + margin / coslat)


def _sd_step_days(span_days: float) -> float:
    """A round spacing (days) giving about SD_CIRCLES uncertainty circles along the track."""
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


def _draw_ellipses(ax: Axes, track: pd.DataFrame, times: NDArray, lat: NDArray, lon: NDArray, colors: NDArray):
    """Draw the 95% ellipse every few days (a circle of radius 2 sd_km when the track has no
    ellipse columns); return the spacing in days (None if none drawn)."""
    sd = _column(track, "sd_km")
    if "smaj_km" in track:
        axes = np.column_stack([_column(track, "smaj_km"), _column(track, "smin_km"), _column(track, "angle_deg")])
    else:
        axes = np.column_stack([sd / np.sqrt(2.0), sd / np.sqrt(2.0), np.zeros_like(sd)])
    if len(times) == 0 or not np.isfinite(axes[:, 0]).any():
        return None
    step = _sd_step_days((times[-1] - times[0]) / np.timedelta64(1, "D"))
    drawn = False
    for k in _sd_indices(times, step):
        if not (np.all(np.isfinite(axes[k])) and np.isfinite(lat[k]) and np.isfinite(lon[k])):
            continue
        vertices = _ellipse_polygon(lat[k], lon[k], *axes[k])
        ax.add_patch(Polygon(vertices, fc=(*colors[k][:3], 0.25), ec=(0.0, 0.0, 0.0, 0.7), lw=0.7, zorder=3.5))
        drawn = True
    return step if drawn else None


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


def _draw_beacons(ax: Axes, beacons: BeaconTable, keep: NDArray[np.bool_], ref_lon: float) -> None:
    """Beacons as black triangles labelled with their ids."""
    if not keep.any():
        return
    lon = _unwrap_lon(beacons.lon[keep], ref_lon)
    lat = beacons.lat[keep]
    ax.scatter(lon, lat, marker="^", s=70, c="k", edgecolors="w", linewidths=0.8, zorder=5, label="beacon")
    for b, x, y in zip(beacons.beacon_id[keep], lon, lat, strict=True):
        ax.annotate(
            str(b),
            (x, y),
            xytext=(5, 5),
            textcoords="offset points",
            fontsize=8,
            zorder=6,
            bbox={"boxstyle": "round,pad=0.15", "fc": "w", "ec": "none", "alpha": 0.7},
        )


def _draw_fixes(ax: Axes, info: FloatInfo, ref_lon: float) -> None:
    """Launch fix (green circle) and, when known, end fix (red square)."""
    fixes = [(info.launch_lat, info.launch_lon, info.launch_time, "o", 10, "tab:green", "launch")]
    if info.has_end_fix:
        fixes.append((info.end_lat, info.end_lon, info.end_time, "s", 9, "tab:red", "end fix"))
    for lat, lon, when, marker, size, color, name in fixes:
        label = f"{name} {np.datetime_as_string(when, 'D')}"
        ax.plot(_unwrap_lon(lon, ref_lon), lat, marker, ms=size, mfc=color, mec="k", zorder=7, label=label)


def _time_norm(tnum: NDArray) -> Normalize:
    """Colour normalisation over the track's dates (a one-day span for a single time)."""
    lo, hi = float(tnum.min()), float(tnum.max())
    return Normalize(lo, hi) if hi > lo else Normalize(lo - 0.5, hi + 0.5)


def plot_track(
    track: pd.DataFrame,
    beacons: BeaconTable,
    info: FloatInfo,
    path: Path,
    truth: pd.DataFrame | None = None,
    modes: pd.DataFrame | None = None,
) -> Path:
    """Map of the estimated track coloured by time, with 95% ellipses, ambiguous positions and
    their second modes, beacons, fixes and optional truth."""
    times = _times(track)
    lat, lon_raw = _column(track, "lat"), _column(track, "lon")
    ref_lon = _reference_lon(lon_raw, info.launch_lon)
    lon = _unwrap_lon(lon_raw, ref_lon)
    mean_lat = float(np.nanmean(lat)) if np.isfinite(lat).any() else info.launch_lat
    with figure() as fig:
        ax = fig.add_subplot()
        handles: list[object] = []
        if len(times):
            tnum = mdates.date2num(times)
            norm = _time_norm(tnum)
            cmap = matplotlib.colormaps[TIME_CMAP]
            colors = cmap(norm(tnum))
            ax.plot(lon, lat, "-", color="0.55", lw=0.8, zorder=2)
            ax.scatter(lon, lat, c=colors, s=10, zorder=3, label="estimated track")
            step = _draw_ellipses(ax, track, times, lat, lon, colors)
            if step is not None:
                handles.append(
                    Patch(fc=(*cmap(0.5)[:3], 0.25), ec="k", lw=0.7, label=f"95% ellipse (every {step:g} d)")
                )
            _draw_modes(ax, track, modes, ref_lon)
            if float(norm.vmax or 0.0) - float(norm.vmin or 0.0) > 1.0:  # a colour scale means nothing for one window
                cbar = fig.colorbar(ScalarMappable(norm, cmap), ax=ax, shrink=0.9, pad=0.01)
                date_axis(cbar.ax.yaxis)
        else:
            _note(ax, "no track estimate")
        if truth is not None and len(truth):
            tlon = _unwrap_lon(_column(truth, "lon"), ref_lon)
            ax.plot(tlon, _column(truth, "lat"), "--", color="k", lw=1.2, zorder=4, label="truth")
        keep = _select_beacons(beacons, np.append(lat, info.launch_lat), np.append(lon, info.launch_lon))
        _draw_beacons(ax, beacons, keep, ref_lon)
        _draw_fixes(ax, info, ref_lon)
        draw_context(ax, *ax.get_ylim(), *ax.get_xlim(), context=float_context(info.float_id))
        ax.set_aspect(1.0 / max(np.cos(np.radians(mean_lat)), 0.05), adjustable="datalim")
        ax.set_xlabel("longitude (°E)")
        ax.set_ylabel("latitude (°N)")
        ax.grid(True, lw=0.4, alpha=0.5)
        legend_handles, _ = ax.get_legend_handles_labels()
        hidden = int((~keep).sum())
        if hidden:
            handles.append(Line2D([], [], ls="none", label=f"{hidden} distant beacon(s) not shown"))
        all_handles = legend_handles + handles
        fig.legend(
            handles=all_handles,
            loc="outside lower center",
            fontsize=8,
            frameon=False,
            ncols=min(len(all_handles), 4),
        )
        ax.set_title(f"Float {info.float_id}: estimated track" + _span_text(times))
        return save_png(fig, path)


def _span_text(times: NDArray[np.datetime64]) -> str:
    """' (first – last, n windows)' for a title, or '' when empty."""
    if not len(times):
        return ""
    first = np.datetime_as_string(times.min(), "D")
    last = np.datetime_as_string(times.max(), "D")
    plural = "" if len(times) == 1 else "s"
    return f" ({first} – {last}, {len(times)} window{plural})"
