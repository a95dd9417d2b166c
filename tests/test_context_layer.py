"""The map's context layer: coastline always, depth contours with a grid, limits kept."""

from __future__ import annotations

import numpy as np
from matplotlib.collections import PolyCollection

from papers.context import floats_ridge
from rafostrack.config import load_config
from rafostrack.context.floats import build_context, mission_region
from rafostrack.plots import figure
from rafostrack.plots.context_layer import draw_context
from rafostrack.sim.scenarios import synthetic_scenario


def test_coastline_is_drawn_and_limits_are_kept():
    with figure() as fig:
        ax = fig.add_subplot()
        ax.plot([-70.0, -64.0], [-56.0, -53.0], "k-")  # around Tierra del Fuego
        limits = ax.get_xlim(), ax.get_ylim()
        draw_context(ax, *ax.get_ylim(), *ax.get_xlim())
        assert (ax.get_xlim(), ax.get_ylim()) == limits
        land = [c for c in ax.collections if isinstance(c, PolyCollection)]
        assert land and len(land[0].get_paths()) > 10


def test_depth_contours_with_a_grid(tmp_path):
    beacons, floats = synthetic_scenario(days=10, rng=1)
    info = floats[0]
    path = floats_ridge.write_ridge_grid(tmp_path / "ridge.nc", info, cell_arcmin=4.0)
    settings = load_config(overrides={"context": {"bathymetry": str(path)}}).context
    context = build_context(settings, mission_region(info, beacons, 0.5), 1000.0)
    with figure() as fig:
        ax = fig.add_subplot()
        ax.plot([info.launch_lon - 1, info.launch_lon + 1.5], [info.launch_lat - 0.5, info.launch_lat + 0.5], "k.")
        limits = ax.get_xlim(), ax.get_ylim()
        before = len(ax.collections)
        draw_context(ax, *ax.get_ylim(), *ax.get_xlim(), context=context)
        assert (ax.get_xlim(), ax.get_ylim()) == limits
        assert len(ax.collections) > before  # isobaths, the float's depth, the forbidden shading
    cf = context.grid.cf_at(np.array([info.launch_lon]), np.array([info.launch_lat]))
    assert cf[0] > 0.99  # the launch is 40 km from the crest, in 3000+ m of water
