"""Modes of a particle cloud: connected components of particles on a grid.

A float's posterior can split into separate modes: the mirror image of the float across
the line through two sources fits their arrival times as well as the float itself, and
after a gap or an outage the arrival times may fit at several places. A particle filter
that resamples the whole cloud at once keeps each mode only by chance: the lighter one
thins out at every resampling, even when the data favour neither, and is gone long before
the recovery fix at the end of the mission could tell which was right. The filter
therefore resamples within modes (`resampling.resample_within`), each mode keeping its
own mass (Vermaak, Doucet & Perez 2003, "Maintaining multi-modality through mixture
tracking"); a mode's mass changes only with the evidence of the data.

Modes are found here as connected components: particles are binned into square cells of
side `link_km` in the tangent plane of the cloud's heaviest particle, and two occupied
cells that touch (8-neighbourhood) belong to the same mode. Two groups of particles
separated by more than about `link_km` of empty sea are separate modes; cost O(N) on a
dense grid of the cloud's cells, O(N log N) when the cloud is spread thin.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

from ..model.geodesy import local_offsets_km

_KEY = 1 << 32  # cell key = ix * _KEY + iy (cells within +-2^31 of the reference)
_NEIGHBOURS = np.array([(1, 0), (0, 1), (1, 1), (1, -1)], dtype=np.int64)  # each touching pair of cells once
# A cloud whose bounding box spans at most this many cells per particle is labelled on a
# dense grid of its cells (`_grid_components`, O(N + cells)); a sparser one by sorting.
_DENSE_CELLS_PER_PARTICLE = 16


def mode_labels(lat: NDArray, lon: NDArray, weights: NDArray, link_km: float) -> NDArray[np.intp]:
    """Mode index (0, 1, ...) of each particle, modes ordered by decreasing mass."""
    ref = int(np.argmax(weights))
    east, north = local_offsets_km(lat, lon, lat[ref], lon[ref])
    ix, iy = np.floor(east / link_km).astype(np.int64), np.floor(north / link_km).astype(np.int64)
    nx, ny = int(np.ptp(ix)) + 1, int(np.ptp(iy)) + 1
    if nx <= 2 and ny <= 2:  # at most 2 x 2 cells: all touch, one mode
        return np.zeros(len(weights), dtype=np.intp)
    if nx * ny <= _DENSE_CELLS_PER_PARTICLE * len(weights):
        labels, n_modes = _grid_components(ix - ix.min(), iy - iy.min(), nx, ny)
    else:
        labels, n_modes = _cell_components(ix * _KEY + iy, _NEIGHBOURS)
    mass = np.bincount(labels, weights=weights, minlength=n_modes)
    rank = np.empty(n_modes, dtype=np.intp)
    rank[np.argsort(-mass, kind="stable")] = np.arange(n_modes)
    return rank[labels]


@njit(cache=True, nogil=True)
def _cell_components(key, neighbours):  # pragma: no cover - compiled
    """Per particle, the connected component of its cell among the occupied cells (cells
    touching by `neighbours` offsets, each pair once), and the number of components; the
    components numbered in the order of their first cells by key. Union-find over the
    cells sorted by key, each neighbour found by binary search: O(N log N)."""
    n = key.shape[0]
    order = np.argsort(key, kind="mergesort")
    cells = np.empty(n, dtype=np.int64)
    cell_of = np.empty(n, dtype=np.int64)
    m = 0
    for t in range(n):
        p = order[t]
        if m == 0 or key[p] != cells[m - 1]:
            cells[m] = key[p]
            m += 1
        cell_of[p] = m - 1
    cells = cells[:m]
    parent = np.arange(m)
    for c in range(m):
        for q in range(neighbours.shape[0]):
            target = cells[c] + neighbours[q, 0] * _KEY + neighbours[q, 1]
            at = np.searchsorted(cells, target)
            if at < m and cells[at] == target:
                a, b = _root(parent, c), _root(parent, at)
                if a != b:
                    parent[max(a, b)] = min(a, b)
    component = np.full(m, -1, dtype=np.int64)
    cell_label = np.empty(m, dtype=np.int64)
    count = 0
    for c in range(m):
        r = _root(parent, c)
        if component[r] < 0:
            component[r] = count
            count += 1
        cell_label[c] = component[r]
    labels = np.empty(n, dtype=np.intp)
    for p in range(n):
        labels[p] = cell_label[cell_of[p]]
    return labels, count


@njit(cache=True, nogil=True)
def _grid_components(gx, gy, nx, ny):  # pragma: no cover - compiled
    """`_cell_components` on a dense (nx, ny) grid of cells, particles in cells (gx, gy) >= 0:
    each occupied cell not yet reached starts a component, in (x, y) order (the order of
    `_cell_components`' keys), flooded through its 8 neighbours."""
    empty, unvisited = -1, -2
    grid = np.full((nx, ny), empty, dtype=np.int64)
    for p in range(gx.shape[0]):
        grid[gx[p], gy[p]] = unvisited
    stack = np.empty(nx * ny, dtype=np.int64)
    count = 0
    for x0 in range(nx):
        for y0 in range(ny):
            if grid[x0, y0] != unvisited:
                continue
            grid[x0, y0] = count
            stack[0] = x0 * ny + y0
            top = 1
            while top > 0:
                top -= 1
                x, y = divmod(stack[top], ny)
                for x1 in range(max(x - 1, 0), min(x + 2, nx)):
                    for y1 in range(max(y - 1, 0), min(y + 2, ny)):
                        if grid[x1, y1] == unvisited:
                            grid[x1, y1] = count
                            stack[top] = x1 * ny + y1
                            top += 1
            count += 1
    labels = np.empty(gx.shape[0], dtype=np.intp)
    for p in range(gx.shape[0]):
        labels[p] = grid[gx[p], gy[p]]
    return labels, count


@njit(cache=True, nogil=True)
def _root(parent, c):  # pragma: no cover - compiled
    """The root of cell c's tree, halving the path on the way."""
    while parent[c] != c:
        parent[c] = parent[parent[c]]
        c = parent[c]
    return c
