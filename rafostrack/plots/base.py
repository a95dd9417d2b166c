"""What the plots share: figure and PNG writing, colours, date axes, small helpers.

Figures are built on `matplotlib.figure.Figure` with an Agg canvas (no pyplot global
state, no display needed) and written through `atomic_path`, so a reader never sees a
half-written PNG.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator, Sequence
from pathlib import Path

import matplotlib
import matplotlib.dates as mdates
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
MAX_BEACONS_ALL = 8  # show every beacon on the map when there are at most this many
SD_CIRCLES = 12  # about this many uncertainty ellipses along the track
CLUTTER_COLOR = "0.45"
TIME_CMAP = "viridis"
# tab20 without its greys (reserved for clutter): the ten strong hues, then the light ones.
_TAB20_ORDER = [i for i in range(0, 20, 2) if i != 14] + [i for i in range(1, 20, 2) if i != 15]

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
    """A distinct tab20 colour per beacon id (no greys), cycling beyond 18 beacons."""
    cmap = matplotlib.colormaps["tab20"]
    return {b: cmap(_TAB20_ORDER[k % len(_TAB20_ORDER)]) for k, b in enumerate(ids)}


def date_axis(axis: Axis) -> None:
    """Concise automatic date ticks on `axis`."""
    locator = mdates.AutoDateLocator()
    axis.set_major_locator(locator)
    axis.set_major_formatter(mdates.ConciseDateFormatter(locator))


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
