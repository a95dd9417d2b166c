"""Diagnostic plots of one float's tracking result: map, labelled arrivals, uncertainty.

One module per figure (`track_map`, `arrivals`, `uncertainty`; `mission_map`, every float
of a batch on one map, for the mission overview); `base` holds what they share (atomic PNG
writing, colours, date axes), which the experiments use too.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..config import ModelConfig
from ..domain import BeaconTable, FloatInfo
from ..summaries.estimates import Estimate
from .arrivals import draw_arrivals, plot_arrivals
from .base import beacon_colors, date_axis, figure, save_png
from .track_map import Background, draw_track, plot_track
from .uncertainty import draw_uncertainty, plot_uncertainty

__all__ = [
    "Background",
    "beacon_colors",
    "date_axis",
    "draw_arrivals",
    "draw_track",
    "draw_uncertainty",
    "figure",
    "plot_arrivals",
    "plot_track",
    "plot_uncertainty",
    "save_png",
    "write_plots",
]


def write_plots(
    outdir: Path, estimate: Estimate, beacons: BeaconTable, info: FloatInfo, model: ModelConfig, **extra: Any
) -> list[Path]:
    """Write track.png, arrivals.png and uncertainty.png of `estimate` into `outdir`; return
    their paths. `extra` may give `truth` (a time, lat, lon frame, drawn on the map) and
    `background` (a `track_map.Background` drawing map context, e.g. coastline and depth)."""
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    return [
        plot_track(
            estimate.track,
            beacons,
            info,
            outdir / "track.png",
            truth=extra.get("truth"),
            modes=estimate.modes,
            background=extra.get("background"),
        ),
        plot_arrivals(estimate.labels, estimate.track, beacons, info, model, outdir / "arrivals.png"),
        plot_uncertainty(estimate.track, outdir / "uncertainty.png"),
    ]
