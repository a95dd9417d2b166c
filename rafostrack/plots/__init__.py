"""Diagnostic plots of one float's tracking result: map, labelled arrivals, uncertainty.

One module per figure (`track_map`, `arrivals`, `uncertainty`); `base` holds what they
share (atomic PNG writing, colours, date axes), which the experiments use too.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from ..config import ModelConfig
from ..domain import BeaconTable, FloatInfo
from .arrivals import plot_arrivals
from .base import beacon_colors, date_axis, figure, save_png
from .track_map import plot_track
from .uncertainty import plot_uncertainty

__all__ = [
    "beacon_colors",
    "date_axis",
    "figure",
    "plot_arrivals",
    "plot_track",
    "plot_uncertainty",
    "save_png",
    "write_plots",
]


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
