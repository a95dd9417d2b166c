"""The context grid (paper section II-A): regular cells, a corrective factor per cell, and
the areas A_k the update rule counts entries into.

A cell (i, j) covers x0 + j dx <= x < x0 + (j + 1) dx, y0 + i dy <= y < y0 + (i + 1) dy
(x, y: plane units, or longitude and latitude in degrees with `wrap_x = 360`). Each cell
holds CF = P(m = true | context of the cell), the probability that the target can be
(move) there. The cells' context variables are kept as evidence: `ContextGrid.update`
replaces the evidence of some cells when new context arrives and recomputes their CF with
the Bayesian network (`ContextModel`), so the filter uses it from its next step on.

Areas. The paper's rule multiplies a particle's weight by CF only when it enters a new area
A_k: a set of locations where the context is the same, represented as a cluster of cells
with equal CF (section II-A, option 2). The grid labels its areas as the connected
(4-neighbour) components of cells whose CF falls in the same band: with `band_edges=None`
every distinct CF value is its own band (the paper's map of CF 1 / 0.5 / 0); a continuous CF
(a bathymetry grid's) is cut into bands at `band_edges`. Locations outside the grid are one
area of their own with CF `outside_cf` (1: no context there).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from .bayesnet import DiscreteBayesNet

OUTSIDE = -1  # the area label of locations outside the grid


@dataclass(frozen=True)
class ContextModel:
    """How a cell's context variables give its CF: P(query = true_state | given) from a
    Bayesian network, tabulated once over every combination of the given states."""

    network: DiscreteBayesNet
    query: str
    given: tuple[str, ...]
    true_state: str = "true"
    table: NDArray[np.float64] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        k = self.network.state_index(self.query, self.true_state)
        table = self.network.posterior_table(self.query, self.given)[..., k]
        object.__setattr__(self, "table", table)

    def cf(self, evidence: Mapping[str, NDArray[np.intp]]) -> NDArray[np.float64]:
        """CF for cells with the given evidence (state indices, arrays of one shape)."""
        missing = [g for g in self.given if g not in evidence]
        if missing:
            raise ValueError(f"evidence for {missing} missing")
        index = tuple(np.asarray(evidence[g], dtype=np.intp) for g in self.given)
        out = self.table[index]
        if np.isnan(out).any():
            raise ValueError("some cells have evidence of probability 0 under the network")
        return out


# Cells with a CF below this are forbidden ground when the grid is split into regions.
MIN_ALLOWED_CF = 0.01


def label_regions(cf: NDArray[np.float64]) -> NDArray[np.int64]:
    """Allowed-region labels (0, 1, ...): connected 8-neighbour components of the cells with
    CF >= `MIN_ALLOWED_CF`, so that two points in different regions are parted by forbidden
    ground; `OUTSIDE` on forbidden cells."""
    component, _ = ndimage.label(cf >= MIN_ALLOWED_CF, structure=np.ones((3, 3), dtype=int))
    return np.where(component > 0, component - 1, OUTSIDE).astype(np.int64)


def label_areas(cf: NDArray[np.float64], band_edges: Sequence[float] | None = None) -> NDArray[np.int64]:
    """Area labels (0, 1, ...): connected 4-neighbour components of cells in the same CF band
    (module docstring)."""
    if band_edges is None:
        values, band = np.unique(cf, return_inverse=True)
        band = band.reshape(cf.shape)
        n_bands = len(values)
    else:
        band = np.digitize(cf, np.asarray(band_edges, dtype=float))
        n_bands = len(band_edges) + 1
    labels = np.zeros(cf.shape, dtype=np.int64)
    offset = 0
    for b in range(n_bands):
        component, n = ndimage.label(band == b)
        inside = component > 0
        labels[inside] = component[inside] - 1 + offset
        offset += n
    return labels


@dataclass
class ContextGrid:
    """Regular cells with a CF and an area label each (module docstring)."""

    x0: float
    y0: float
    dx: float
    dy: float
    cf: NDArray[np.float64]  # (ny, nx)
    band_edges: tuple[float, ...] | None = None
    outside_cf: float = 1.0
    wrap_x: float | None = None  # 360.0 for longitude
    model: ContextModel | None = None
    evidence: dict[str, NDArray[np.intp]] | None = None
    area: NDArray[np.int64] = field(init=False)
    region: NDArray[np.int64] = field(init=False)  # allowed regions (`label_regions`)

    def __post_init__(self) -> None:
        self.cf = np.asarray(self.cf, dtype=float)
        if self.cf.ndim != 2 or self.cf.size == 0:
            raise ValueError("cf must be a non-empty 2-D array (rows = y, columns = x)")
        if not (self.dx > 0 and self.dy > 0):
            raise ValueError("cell sizes must be > 0")
        if np.any(~np.isfinite(self.cf)) or np.any((self.cf < 0) | (self.cf > 1)):
            raise ValueError("CF values must be probabilities in [0, 1]")
        if not 0 <= self.outside_cf <= 1:
            raise ValueError("outside_cf must be in [0, 1]")
        self.area = label_areas(self.cf, self.band_edges)
        self.region = label_regions(self.cf)

    @classmethod
    def from_context(
        cls,
        model: ContextModel,
        evidence: Mapping[str, ArrayLike],
        *,
        x0: float,
        y0: float,
        dx: float,
        dy: float,
        **options,
    ) -> ContextGrid:
        """A grid whose CF per cell is the network's P(m = true | the cell's evidence)."""
        ev = {k: np.asarray(v, dtype=np.intp) for k, v in evidence.items()}
        return cls(x0, y0, dx, dy, model.cf(ev), model=model, evidence=ev, **options)

    @property
    def shape(self) -> tuple[int, int]:
        return self.cf.shape  # type: ignore[return-value]

    def update(self, rows: ArrayLike, cols: ArrayLike, **evidence: ArrayLike) -> None:
        """New context for cells (rows, cols): replace their evidence for the named
        variables, recompute their CF with the network, and relabel the areas."""
        if self.model is None or self.evidence is None:
            raise ValueError("this grid has no context model to update from")
        r, c = np.asarray(rows, dtype=np.intp), np.asarray(cols, dtype=np.intp)
        for name, values in evidence.items():
            if name not in self.evidence:
                raise ValueError(f"unknown context variable {name!r}; known: {', '.join(self.evidence)}")
            self.evidence[name][r, c] = np.asarray(values, dtype=np.intp)
        self.cf[r, c] = self.model.cf({k: v[r, c] for k, v in self.evidence.items()})
        self.area = label_areas(self.cf, self.band_edges)
        self.region = label_regions(self.cf)

    def cell_of(self, x: ArrayLike, y: ArrayLike) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.bool_]]:
        """Row, column and whether each point is inside the grid (row, column 0 outside)."""
        x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        rel_x = x - self.x0
        if self.wrap_x is not None:
            rel_x = np.mod(rel_x, self.wrap_x)
        col = np.floor(rel_x / self.dx)
        row = np.floor((y - self.y0) / self.dy)
        ny, nx = self.shape
        inside = (row >= 0) & (row < ny) & (col >= 0) & (col < nx)
        return np.where(inside, row, 0).astype(np.intp), np.where(inside, col, 0).astype(np.intp), inside

    def cf_at(self, x: ArrayLike, y: ArrayLike) -> NDArray[np.float64]:
        """CF of the cells holding the points (`outside_cf` outside the grid)."""
        row, col, inside = self.cell_of(x, y)
        return np.where(inside, self.cf[row, col], self.outside_cf)

    def area_at(self, x: ArrayLike, y: ArrayLike) -> NDArray[np.int64]:
        """Area labels of the points (`OUTSIDE` outside the grid)."""
        row, col, inside = self.cell_of(x, y)
        return np.where(inside, self.area[row, col], OUTSIDE)

    def region_at(self, x: ArrayLike, y: ArrayLike) -> NDArray[np.int64]:
        """Allowed-region labels of the points (`label_regions`; `OUTSIDE` outside the grid or
        on forbidden ground)."""
        row, col, inside = self.cell_of(x, y)
        return np.where(inside, self.region[row, col], OUTSIDE)
