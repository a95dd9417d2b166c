"""Diagnostic plots of one float's tracking result: map, labelled arrivals, uncertainty.

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
from matplotlib.cm import ScalarMappable
from matplotlib.colors import Normalize, to_rgba
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch, Polygon
from matplotlib.ticker import MaxNLocator
from numpy.typing import NDArray

from .config import ModelConfig
from .domain import BeaconTable, FloatInfo
from .estimates import runs_of
from .io.atomic import atomic_path
from .model import predicted_arrivals
from .posterior import ELLIPSE_95_SCALE

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


# --------------------------------------------------------------------------------------
# helpers


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


# --------------------------------------------------------------------------------------
# track map


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
    amb = track[track["ambiguous"]]
    ax.scatter(
        _unwrap_lon(amb["lon"].to_numpy(), ref_lon),
        amb["lat"],
        s=40,
        facecolors="none",
        edgecolors="tab:red",
        linewidths=0.8,
        zorder=4.5,
        label="ambiguous (reported mode)",
    )
    if modes is not None and len(modes):
        second = modes[modes["mode"] == 2]
        ax.scatter(
            _unwrap_lon(second["lon"].to_numpy(), ref_lon),
            second["lat"],
            s=22,
            marker="x",
            c="tab:red",
            linewidths=0.9,
            zorder=4.5,
            label="second mode",
        )
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
    """Launch fix (green) and, when known, end fix (red)."""
    ax.plot(
        _unwrap_lon(info.launch_lon, ref_lon),
        info.launch_lat,
        "o",
        ms=10,
        mfc="tab:green",
        mec="k",
        zorder=7,
        label=f"launch {np.datetime_as_string(info.launch_time, 'D')}",
    )
    if info.has_end_fix:
        ax.plot(
            _unwrap_lon(info.end_lon, ref_lon),
            info.end_lat,
            "s",
            ms=9,
            mfc="tab:red",
            mec="k",
            zorder=7,
            label=f"end fix {np.datetime_as_string(info.end_time, 'D')}",
        )


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
            if norm.vmax - norm.vmin > 1.0:  # a colour scale means nothing for one window
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


# --------------------------------------------------------------------------------------
# labelled arrivals


def _label_ids(labels: pd.DataFrame) -> NDArray[np.object_]:
    """Beacon id per label row as str, None for clutter (None, NaN or empty)."""
    if "beacon_id" not in labels.columns:
        return np.full(len(labels), None, dtype=object)
    raw = labels["beacon_id"]
    clutter = raw.isna() | (raw.astype(str).str.strip() == "")
    return np.where(clutter, None, raw.astype(str)).astype(object)


def _predicted(
    track: pd.DataFrame, beacons: BeaconTable, info: FloatInfo, model: ModelConfig
) -> tuple[NDArray[np.datetime64], NDArray[np.float64]]:
    """Track times and each beacon's predicted TOA along the track, shape (n, n_beacons)."""
    times = _times(track)
    if not len(times):
        return times, np.full((0, len(beacons)), np.nan)
    pred = predicted_arrivals(times, _column(track, "lat"), _column(track, "lon"), beacons, info, model)
    return times, pred


def _beacons_to_show(ids: Sequence[str], counts: dict[str, int], pred: NDArray, window_s: float) -> list[int]:
    """Columns of beacons with a label or a predicted curve inside [0, window_s]."""
    with np.errstate(invalid="ignore"):
        in_window = ((pred >= 0.0) & (pred <= window_s)).any(axis=0)
    return [k for k, b in enumerate(ids) if counts.get(b, 0) > 0 or in_window[k]]


def plot_arrivals(
    labels: pd.DataFrame,
    track: pd.DataFrame,
    beacons: BeaconTable,
    info: FloatInfo,
    model: ModelConfig,
    path: Path,
) -> Path:
    """Stored TOAs against time coloured by assigned beacon, with predicted arrival curves."""
    ids = [str(b) for b in beacons.beacon_id]
    label_ids = _label_ids(labels)
    extra = sorted({b for b in label_ids if b is not None} - set(ids))  # ids unknown to the table
    colors = beacon_colors(ids + extra)
    ltimes, toa, prob = _times(labels), _column(labels, "toa_s"), _column(labels, "prob")
    clutter = np.array([b is None for b in label_ids], dtype=bool)
    counts = pd.Series(label_ids[~clutter]).value_counts().to_dict()
    ptimes, pred = _predicted(track, beacons, info, model)
    shown = _beacons_to_show(ids, counts, pred, info.window_s)
    with figure() as fig:
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
            _arrivals_legend(fig, handles)
        return save_png(fig, path)


def _arrivals_legend(fig: Figure, handles: list[Line2D]) -> None:
    """Legend of beacons (with TOA counts), clutter and predicted curves, right of the axes."""
    fig.legend(
        handles=handles,
        loc="outside right upper",
        fontsize=8,
        title="beacon (n TOAs)",
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
        ax.set_xlim(info.launch_time, end)
    date_axis(ax.xaxis)


def _arrivals_title(info: FloatInfo, label_ids: NDArray[np.object_]) -> str:
    """Title with the float id and TOA counts."""
    n = len(label_ids)
    n_clutter = int(sum(b is None for b in label_ids))
    return (
        f"Float {info.float_id}: {n} stored TOAs, {n - n_clutter} assigned to beacons, {n_clutter} clutter"
        "\n(marker opacity = label probability; lines = predicted arrivals along the estimated track)"
    )


# --------------------------------------------------------------------------------------
# uncertainty


def plot_uncertainty(track: pd.DataFrame, path: Path) -> Path:
    """Posterior spread, stored TOAs per window and effective sample size against time,
    with ambiguous stretches shaded."""
    times = _times(track)
    with figure() as fig:
        ax_sd, ax_n, ax_ess = fig.subplots(3, 1, sharex=True, height_ratios=[2.0, 1.0, 1.3])
        sd, n_sig, ess = _column(track, "sd_km"), _column(track, "n_signals"), _column(track, "ess")
        _line_panel(ax_sd, times, sd, "posterior sd (km)", "tab:blue")
        ms = 4 if len(times) == 1 else 0  # a one-point step line would be invisible
        ax_n.plot(times, n_sig, drawstyle="steps-mid", color="tab:orange", lw=1.0, marker="o", ms=ms)
        ax_n.set_ylabel("stored TOAs")
        ax_n.yaxis.set_major_locator(MaxNLocator(integer=True, nbins=4))
        ax_n.set_ylim(0, max(np.nanmax(n_sig, initial=0.0), 1.0) + 0.5)
        _line_panel(ax_ess, times, ess, "ESS (particles)", "tab:green", log=_wants_log(ess))
        spans = runs_of(_times(track), track["ambiguous"].to_numpy(dtype=bool)) if "ambiguous" in track else []
        for ax in (ax_sd, ax_n, ax_ess):
            ax.grid(True, lw=0.4, alpha=0.5)
            for a, b in spans:
                ax.axvspan(a - np.timedelta64(12, "h"), b + np.timedelta64(12, "h"), color="tab:red", alpha=0.15, lw=0)
        if spans:
            ax_sd.legend(handles=[Patch(color="tab:red", alpha=0.15, label="ambiguous (two modes)")], loc="upper right")
        if len(times):
            pad = max((times.max() - times.min()) * 0.01, np.timedelta64(12, "h"))
            ax_ess.set_xlim(times.min() - pad, times.max() + pad)
            date_axis(ax_ess.xaxis)
        else:
            for ax in (ax_sd, ax_n, ax_ess):
                ax.set_xticks([])
                ax.set_yticks([])
            _note(ax_sd, "no track estimate")
        fid = _float_id(track)
        ax_sd.set_title(f"Float {fid}: posterior uncertainty" if fid else "Posterior uncertainty")
        return save_png(fig, path)


def _line_panel(ax: Axes, times: NDArray, values: NDArray, ylabel: str, color: str, log: bool = False) -> None:
    """A time series with small markers (NaN leaves gaps); a note when all values are missing."""
    ax.plot(times, values, "-", color=color, lw=1.0, marker=".", ms=3)
    ax.set_ylabel(ylabel)
    if log:
        ax.set_yscale("log")
    elif np.isfinite(values).any():
        ax.set_ylim(bottom=0)
    elif len(times):
        _note(ax, "not available")
        ax.set_yticks([])


def _wants_log(values: NDArray) -> bool:
    """Whether positive values span enough (over 30x) to need a log scale."""
    good = values[np.isfinite(values) & (values > 0)]
    return bool(len(good)) and good.max() / good.min() > 30


# --------------------------------------------------------------------------------------
# all plots


def write_plots(
    outdir: Path,
    track: pd.DataFrame,
    labels: pd.DataFrame,
    beacons: BeaconTable,
    info: FloatInfo,
    model: ModelConfig,
    truth: pd.DataFrame | None = None,
    modes: pd.DataFrame | None = None,
) -> list[Path]:
    """Write track.png, arrivals.png and uncertainty.png into `outdir`; return their paths."""
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    return [
        plot_track(track, beacons, info, outdir / "track.png", truth=truth, modes=modes),
        plot_arrivals(labels, track, beacons, info, model, outdir / "arrivals.png"),
        plot_uncertainty(track, outdir / "uncertainty.png"),
    ]
