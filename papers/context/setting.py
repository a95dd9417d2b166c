"""The paper's synthetic setting (section III): a map of CF 1 / 0.5 / 0, a target from (5, 75)
to (2, 12) in 3000 steps, a measurement every 50 steps with sigma 10.

The paper shows its map only as a picture; ours follows its description. The map is 100 x 100
units in cells of 1 unit, y growing southwards as image rows (the paper's end point (2, 12)
is in the north-west). Each cell's context is a GIS surface label (open, marsh, lake), the
intelligence about it (none) and the vehicle type (car); the context network of Fig. 1,
    gis -> surface;  surface, intel, vehicle -> mobility,
with P(surface | gis): open -> hard, marsh -> hard or soft (1/2 each), lake -> water, and a
car mobile on hard ground without a flood report (P = 0.2 with one), never on soft ground or
water, gives CF = P(mobility | gis, intel, vehicle) = 1 (open), 0.5 (marsh), 0 (lake).
A wide marsh covers the south-west, where the target starts; lakes sit beyond the target's
sharp turns, where a constant-velocity model overshoots. Experiment C's three sensors are
range-limited (circles), leaving two of the turns unseen.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from rafostrack.context.bayesnet import DiscreteBayesNet, Node, binary_cpt
from rafostrack.context.grid import ContextGrid, ContextModel
from rafostrack.context.planar import Sensor, polyline_truth

MAP_SIZE = 100
N_STEPS = 3000
EVERY = 50
SIGMA = 10.0
START = (5.0, 75.0)
END = (2.0, 12.0)
WAYPOINTS = (START, (28.0, 90.0), (65.0, 90.0), (65.0, 50.0), (88.0, 50.0), (88.0, 20.0), (30.0, 20.0), END)
# Rectangles (x0, x1, y0, y1) of marsh and of lakes; the rest of the map is open ground.
MARSH = ((0.0, 48.0, 62.0, 100.0),)
LAKES = (
    (72.0, 100.0, 58.0, 100.0),  # beyond the first turn (east, then north)
    (50.0, 80.0, 28.0, 44.0),  # beyond the second (north, then east)
    (93.0, 100.0, 0.0, 58.0),  # beyond the third (east, then north)
    (60.0, 100.0, 0.0, 13.0),  # beyond the fourth (north, then west)
    (12.0, 45.0, 30.0, 50.0),  # between the marsh and the last leg
)
# Experiment C: three sensors with a range (the paper's Fig. 6a circles).
PARTIAL_SENSORS = (Sensor(18.0, 80.0, 22.0), Sensor(76.0, 40.0, 20.0), Sensor(40.0, 16.0, 18.0))
FULL_SENSORS = (Sensor(50.0, 50.0),)  # "a radar-like sensor that can observe the whole area"

GIS = ("open", "marsh", "lake")


def context_network() -> DiscreteBayesNet:
    """The Fig. 1 network (module docstring)."""
    surface_given_gis = np.array([[1.0, 0.0, 0.0], [0.5, 0.5, 0.0], [0.0, 0.0, 1.0]])
    # P(mobile | surface (hard, soft, water), intel (none, flooded), vehicle (car, boat))
    p_mobile = np.zeros((3, 2, 2))
    p_mobile[0, 0, 0], p_mobile[0, 1, 0] = 1.0, 0.2  # a car on hard ground, with / without a flood report
    p_mobile[2, :, 1] = 1.0  # a boat on water
    return DiscreteBayesNet(
        [
            Node("gis", GIS, (), np.full(3, 1.0 / 3.0)),
            Node("surface", ("hard", "soft", "water"), ("gis",), surface_given_gis),
            Node("intel", ("none", "flooded"), (), np.array([0.9, 0.1])),
            Node("vehicle", ("car", "boat"), (), np.array([0.5, 0.5])),
            Node("mobility", ("false", "true"), ("surface", "intel", "vehicle"), binary_cpt(p_mobile)),
        ]
    )


def gis_labels() -> NDArray[np.intp]:
    """The map's GIS label per cell (rows = y, southwards)."""
    centre = np.arange(MAP_SIZE) + 0.5
    x, y = np.meshgrid(centre, centre)
    labels = np.zeros((MAP_SIZE, MAP_SIZE), dtype=np.intp)
    for value, boxes in ((1, MARSH), (2, LAKES)):
        for x0, x1, y0, y1 in boxes:
            labels[(x >= x0) & (x < x1) & (y >= y0) & (y < y1)] = value
    return labels


def context_grid() -> ContextGrid:
    """The map as a context grid whose CF comes from the network (CF 1 / 0.5 / 0)."""
    gis = gis_labels()
    model = ContextModel(context_network(), "mobility", ("gis", "intel", "vehicle"))
    evidence = {"gis": gis, "intel": np.zeros_like(gis), "vehicle": np.zeros_like(gis)}
    return ContextGrid.from_context(model, evidence, x0=0.0, y0=0.0, dx=1.0, dy=1.0, outside_cf=0.0)


def truth_track() -> NDArray[np.float64]:
    """The target at steps 0..N_STEPS."""
    return polyline_truth(WAYPOINTS, N_STEPS)


@dataclass(frozen=True)
class FilterSettings:
    """The filter's motion model (not given in the paper: nearly constant velocity, tuned to
    the target's speed) and its prior around the start."""

    accel_sd: float = 0.004  # units per step^2
    prior_sd: float = 2.0
    speed_sd: float = 0.08  # sd of the initial velocity per axis (the target's speed ~0.08)

    def describe(self) -> str:
        return (
            f"nearly constant velocity, acceleration sd {self.accel_sd:g} units/step², prior N(start, "
            f"{self.prior_sd:g}²) in position and N(0, {self.speed_sd:g}²) per axis in velocity"
        )
