"""The context grid: cells, areas, and updates when new context arrives."""

from __future__ import annotations

import numpy as np
import pytest

from papers.context.setting import context_grid, context_network
from rafostrack.context.grid import OUTSIDE, ContextGrid, ContextModel, label_areas


def test_cells_and_outside():
    grid = ContextGrid(10.0, -5.0, 2.0, 1.0, np.array([[1.0, 0.5, 0.0]]), outside_cf=0.25)
    _row, col, inside = grid.cell_of([10.0, 13.9, 15.99, 16.0, 9.99], [-5.0, -4.5, -4.01, -4.5, -4.5])
    assert inside.tolist() == [True, True, True, False, False]
    assert col[:3].tolist() == [0, 1, 2]
    assert grid.cf_at([11.0, 13.0, 15.0, 20.0], [-4.5] * 4).tolist() == [1.0, 0.5, 0.0, 0.25]
    assert grid.area_at([20.0], [-4.5])[0] == OUTSIDE
    wrapped = ContextGrid(350.0, 0.0, 5.0, 1.0, np.array([[1.0, 0.5, 0.0, 1.0]]), wrap_x=360.0)
    assert wrapped.cf_at([-3.0, 2.0, 362.0, -7.0], [0.5] * 4).tolist() == [0.5, 0.0, 0.0, 1.0]


def test_areas_are_connected_cells_of_like_cf():
    cf = np.array([[1.0, 1.0, 0.5, 1.0], [0.5, 0.5, 0.5, 1.0], [1.0, 0.0, 0.0, 1.0]])
    labels = label_areas(cf)
    assert labels[0, 0] == labels[0, 1] != labels[0, 3]  # two separate CF-1 regions
    assert labels[0, 2] == labels[1, 0]  # one CF-0.5 region
    assert labels[2, 0] not in (labels[0, 0], labels[0, 3])
    banded = label_areas(np.array([[0.99, 0.985, 0.6, 0.7]]), band_edges=(0.5, 0.98))
    assert banded[0, 0] == banded[0, 1] and banded[0, 2] == banded[0, 3] and banded[0, 1] != banded[0, 2]
    with pytest.raises(ValueError):
        ContextGrid(0.0, 0.0, 1.0, 1.0, np.array([[1.2]]))


def test_the_paper_map_comes_from_the_network_and_updates():
    grid = context_grid()
    assert sorted(np.unique(grid.cf).tolist()) == [0.0, 0.5, 1.0]
    assert grid.cf_at([5.0], [75.0])[0] == 0.5  # the start, in the marsh
    x, y = 20.5, 20.5  # open ground on the last leg
    row, col, _ = grid.cell_of([x], [y])
    before = grid.area_at([x], [y])[0]
    grid.update(row, col, intel=[1])  # a flood report for one cell
    assert grid.cf_at([x], [y])[0] == pytest.approx(0.2)
    assert grid.area_at([x], [y])[0] != before  # a new area of its own
    model = ContextModel(context_network(), "mobility", ("gis", "intel", "vehicle"))
    assert model.cf({"gis": np.array([1]), "intel": np.array([0]), "vehicle": np.array([0])})[0] == 0.5
    assert model.cf({"gis": np.array([2]), "intel": np.array([0]), "vehicle": np.array([1])})[0] == 1.0  # a boat
    with pytest.raises(ValueError, match="unknown context variable"):
        grid.update(row, col, weather=[0])
