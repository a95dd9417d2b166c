"""What the plots share: figure and PNG writing, colours, date axes, small helpers.

Figures are built on `matplotlib.figure.Figure` with an Agg canvas (no pyplot global
state, no display needed) and written through `atomic_path`, so a reader never sees a
half-written PNG.
"""

from __future__ import annotations

import contextlib
import datetime
from collections.abc import Iterator, Sequence
from pathlib import Path

import matplotlib
import matplotlib.dates as mdates
import matplotlib.ticker
import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.axis import Axis
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import to_rgba
from matplotlib.figure import Figure
from numpy.typing import NDArray

from ..io.atomic import atomic_path

FIGSIZE = (10.0, 6.0)
DPI = 120
KM_PER_DEG = 111.2
SD_CIRCLES = 12  # about this many uncertainty ellipses along the track
CLUTTER_COLOR = "0.45"
TIME_LABEL = "time (UTC)"  # a date axis's label, before the months and years it spans (`date_axis`)
TIME_CMAP = "viridis"
# 20 beacon colours told apart: every two of them, and each against the clutter grey and a
# white background, differ by at least 20 CIEDE2000 units (tab20's light/dark pairs: 12).
# Chosen greedily (each the sRGB colour on a 13-level grid farthest, in CIEDE2000, from those
# already chosen, the grey and white; greys, very dark and very light colours excluded),
# starting from matplotlib's default blue.
BEACON_PALETTE = (
    "#1580bf", "#5500aa", "#00d400", "#ff6aff", "#ff9500", "#800000", "#ff4055", "#005500", "#00bfbf", "#808000",
    "#aa2a6a", "#554015", "#aabfff", "#806abf", "#d4bf00", "#00806a", "#00406a", "#ffaabf", "#aa6a40", "#80aa80",
)  # fmt: skip

Color = tuple[float, float, float, float]


@contextlib.contextmanager
def figure(width: float = FIGSIZE[0], height: float = FIGSIZE[1], dpi: int = DPI) -> Iterator[Figure]:
    """A fresh Agg-backed figure (no pyplot state) with constrained layout, cleared on exit."""
    fig = Figure(figsize=(width, height), dpi=dpi, layout="constrained")
    FigureCanvasAgg(fig)
    try:
        yield fig
    finally:
        fig.clear()


def save_png(fig: Figure, path: Path) -> Path:
    """Write `fig` as a PNG (at the figure's dpi) to `path` atomically."""
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=fig.dpi)
    return path


def beacon_colors(ids: Sequence[str]) -> dict[str, Color]:
    """A distinct colour per beacon id (`BEACON_PALETTE`: no greys), cycling beyond 20 beacons."""
    return {b: to_rgba(BEACON_PALETTE[k % len(BEACON_PALETTE)]) for k, b in enumerate(ids)}


def degree_text(value: float, positive: str, negative: str) -> str:
    """'58.5°S', '105°W', '0°': a coordinate in degrees with its hemisphere letter."""
    value = round(float(value), 4) + 0.0
    letter = "" if value == 0 else positive if value > 0 else negative
    return f"{abs(value):g}°{letter}"


def lon_text(lon: float, _pos: object = None) -> str:
    """A longitude label, wrapped into [-180, 180) first."""
    return degree_text((float(lon) + 180.0) % 360.0 - 180.0, "E", "W")


def lat_text(lat: float, _pos: object = None) -> str:
    return degree_text(lat, "N", "S")


def date_ticks(axis: Axis, first: np.datetime64, last: np.datetime64) -> None:
    """Plain date ticks at whole days, months or years, about 4 to 8 of them over
    [first, last]: '03 Jan' within a few months, 'Jan 2010' within a few years, '2010' beyond."""
    days = max(float((last - first) / np.timedelta64(1, "D")), 1.0)
    locator: mdates.DateLocator
    if days <= 90:
        step = next(s for s in (1, 2, 3, 5, 7, 14, 21, 30) if days / s <= 7)
        locator, fmt = mdates.DayLocator(interval=step), "%d %b"
    elif days <= 5 * 365:
        months = days / 30.44
        step = next(s for s in (1, 2, 3, 4, 6, 12) if months / s <= 7)
        locator, fmt = mdates.MonthLocator(interval=step), "%b %Y"
    else:
        locator, fmt = mdates.YearLocator(base=max(1, int(np.ceil(days / 365.25 / 7)))), "%Y"
    axis.set_major_locator(locator)
    axis.set_major_formatter(mdates.DateFormatter(fmt))
    axis.set_minor_locator(matplotlib.ticker.NullLocator())


def date_axis(axis: Axis, label: str | None = None) -> None:
    """Concise automatic date ticks on `axis`; with `label`, the axis labelled '<label>, Jan
    2010' (the months and years of the data drawn within its limits, set before) in place of
    the formatter's offset text."""
    locator = mdates.AutoDateLocator()
    axis.set_major_locator(locator)
    axis.set_major_formatter(mdates.ConciseDateFormatter(locator, show_offset=label is None))
    if label is not None:
        (view0, view1), (data0, data1) = sorted(axis.get_view_interval()), axis.get_data_interval()
        first, last = max(view0, data0), min(view1, data1)
        if not first <= last:  # nothing drawn within the limits
            first, last = view0, view1
        axis.set_label_text(f"{label}, {span_text(mdates.num2date(first), mdates.num2date(last))}")


def span_text(first: datetime.datetime, last: datetime.datetime) -> str:
    """'Jan 2010', 'Jan–Mar 2010' or 'Dec 2009 – Feb 2010': the months and years from `first` to `last`."""
    if (first.year, first.month) == (last.year, last.month):
        return f"{first:%b %Y}"
    if first.year == last.year:
        return f"{first:%b}–{last:%b %Y}"
    return f"{first:%b %Y} – {last:%b %Y}"


def _times(frame: pd.DataFrame) -> NDArray[np.datetime64]:
    """The frame's `time` column as datetime64[ns] (empty if absent)."""
    if "time" not in frame.columns:
        return np.array([], dtype="datetime64[ns]")
    return pd.to_datetime(frame["time"]).to_numpy(dtype="datetime64[ns]")


def _column(frame: pd.DataFrame, col: str) -> NDArray[np.float64]:
    """A numeric column as floats (NaN where missing or absent)."""
    if col not in frame.columns:
        return np.full(len(frame), np.nan)
    return pd.to_numeric(frame[col], errors="coerce").to_numpy(dtype=float)


def float_name(float_id: str) -> str:
    """'float767' as is (an id already saying 'float' is not repeated), 'F01' as 'Float F01'."""
    return float_id if float_id.lower().startswith("float") else f"Float {float_id}"


def _float_id(track: pd.DataFrame, default: str = "") -> str:
    """The float id of a track frame, or `default` when it has none."""
    if "float_id" in track.columns and len(track):
        return str(track["float_id"].iloc[0])
    return default


def _unwrap_lon(lon: NDArray | float, ref: float) -> NDArray[np.float64]:
    """Longitudes shifted by whole turns to lie within 180 deg of `ref` (dateline-safe)."""
    return ref + (np.asarray(lon, dtype=float) - ref + 180.0) % 360.0 - 180.0


def _reference_lon(lon: NDArray, fallback: float) -> float:
    """Circular mean of the finite longitudes, or `fallback` when there are none."""
    lon = lon[np.isfinite(lon)]
    if not len(lon):
        return float(fallback)
    rad = np.radians(lon)
    return float(np.degrees(np.arctan2(np.sin(rad).mean(), np.cos(rad).mean())))


def _alpha(prob: NDArray) -> NDArray[np.float64]:
    """Marker opacity from a label probability: faint when unsure, opaque when certain."""
    return np.where(np.isfinite(prob), 0.15 + 0.85 * np.clip(prob, 0.0, 1.0), 1.0)


def _rgba(color: Color | str, alpha: NDArray) -> NDArray[np.float64]:
    """One RGBA row per point: `color` with per-point alpha."""
    rgba = np.tile(to_rgba(color), (len(alpha), 1))
    rgba[:, 3] = alpha
    return rgba


def _note(ax: Axes, text: str) -> None:
    """A grey message in the middle of an axes (used for empty data)."""
    ax.text(0.5, 0.5, text, transform=ax.transAxes, ha="center", va="center", color="0.4", fontsize=12)
