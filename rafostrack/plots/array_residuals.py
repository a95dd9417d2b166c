"""The mission's array, one panel per source: every float's arrival residuals against time
with the tables as given (grey) and with the array the mission fitted (in the float's
colour). A wrong offset shows as a grey band off zero on every float, a wrong drift as a
grey slope, a wrong position as grey bands that differ between floats at other bearings;
after the fit, each source's residuals lie about zero."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import matplotlib
import numpy as np
from numpy.typing import NDArray

from .base import TIME_LABEL, date_axis, figure, save_png

PANEL_SIZE_IN = (3.6, 2.4)
MAX_RESIDUAL_S = 60.0  # residuals beyond are drawn at the edge


@dataclass(frozen=True)
class SourcePanel:
    """One source's residuals: per arrival its time, float (index into the figure's float
    names), residual before and after the fit (s); the panel's title."""

    title: str
    time: NDArray[np.datetime64]
    float_index: NDArray[np.intp]
    before_s: NDArray[np.float64]
    after_s: NDArray[np.float64]


def plot_array_residuals(path: Path, panels: Sequence[SourcePanel], float_names: Sequence[str]) -> Path:
    """`array.png`: a grid of source panels (module docstring)."""
    columns = min(4, max(1, len(panels)))
    rows = max(1, int(np.ceil(len(panels) / columns)))
    colours = matplotlib.colormaps["tab20"](np.arange(len(float_names)) % 20)
    with figure(PANEL_SIZE_IN[0] * columns, PANEL_SIZE_IN[1] * rows + 0.6) as fig:
        axes = fig.subplots(rows, columns, squeeze=False, sharex=True, sharey=True)
        for ax, panel in zip(axes.ravel(), panels, strict=False):
            t = panel.time.astype("datetime64[ms]").astype(object)
            ax.scatter(t, np.clip(panel.before_s, -MAX_RESIDUAL_S, MAX_RESIDUAL_S), s=2, color="0.7", lw=0)
            after = np.clip(panel.after_s, -MAX_RESIDUAL_S, MAX_RESIDUAL_S)
            ax.scatter(t, after, s=2, color=colours[panel.float_index], lw=0)
            ax.axhline(0.0, color="k", lw=0.6)
            ax.set_title(panel.title, fontsize=8)
            ax.tick_params(labelsize=7)
        for ax in axes.ravel()[len(panels) :]:
            ax.set_visible(False)
        label_dates_below(axes, len(panels))
        for ax in axes[:, 0]:
            ax.set_ylabel("residual (s)", fontsize=8)
        fig.suptitle(
            f"Arrival residuals per source: grey with the tables as given, coloured with the fitted array "
            f"({len(float_names)} floats)",
            fontsize=9,
        )
        return save_png(fig, path)


def label_dates_below(axes: NDArray, n_panels: int) -> None:
    """Date ticks under the lowest panel of each column of `axes` (rows, columns; the first
    `n_panels` in row order drawn, their time axis shared), with the axis label and the
    months and years they span (`date_axis`): once per column, not a year on every panel."""
    rows, columns = axes.shape
    for column in range(columns):
        drawn = [r for r in range(rows) if r * columns + column < n_panels]
        if not drawn:
            continue
        lowest = axes[drawn[-1], column]
        lowest.xaxis.set_tick_params(labelbottom=True)
        date_axis(lowest.xaxis, TIME_LABEL)
        lowest.xaxis.label.set_fontsize(7)
