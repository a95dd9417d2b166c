"""`uncertainty.png`: posterior sd, stored TOAs and ESS against time, ambiguous stretches shaded."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.patches import Patch
from matplotlib.ticker import MaxNLocator
from numpy.typing import NDArray

from ..summaries.estimates import runs_of
from .base import TIME_LABEL, _column, _float_id, _note, _times, date_axis, figure, float_name, save_png


def plot_uncertainty(track: pd.DataFrame, path: Path) -> Path:
    """`draw_uncertainty` into a new figure, written as a PNG to `path`."""
    with figure() as fig:
        draw_uncertainty(fig, track)
        return save_png(fig, path)


def draw_uncertainty(fig: Figure, track: pd.DataFrame) -> Figure:
    """Posterior spread, stored TOAs per window and effective sample size against time,
    with ambiguous stretches shaded."""
    times = _times(track)
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
    if spans:  # above the panels, off the data
        fig.legend(
            handles=[Patch(color="tab:red", alpha=0.15, label="ambiguous (two modes)")],
            loc="outside upper right",
            fontsize=8,
            frameon=False,
        )
    if len(times):
        pad = max((times.max() - times.min()) * 0.01, np.timedelta64(12, "h"))
        ax_ess.set_xlim(times.min() - pad, times.max() + pad)
        date_axis(ax_ess.xaxis, TIME_LABEL)
    else:
        for ax in (ax_sd, ax_n, ax_ess):
            ax.set_xticks([])
            ax.set_yticks([])
        _note(ax_sd, "no track estimate")
    fid = _float_id(track)
    ax_sd.set_title(f"{float_name(fid)}: posterior uncertainty" if fid else "Posterior uncertainty")
    return fig


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
