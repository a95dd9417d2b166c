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
separated by more than about `link_km` of empty sea are separate modes; cost O(N log N).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from .geodesy import local_offsets_km

_KEY = np.int64(1) << 32  # cell key = ix * _KEY + iy (cells within +-2^31 of the reference)
_NEIGHBOURS = ((1, 0), (0, 1), (1, 1), (1, -1))  # each touching pair of cells once


def mode_labels(lat: NDArray, lon: NDArray, weights: NDArray, link_km: float) -> NDArray[np.intp]:
    """Mode index (0, 1, ...) of each particle, modes ordered by decreasing mass."""
    ref = int(np.argmax(weights))
    east, north = local_offsets_km(lat, lon, lat[ref], lon[ref])
    ix, iy = np.floor(east / link_km).astype(np.int64), np.floor(north / link_km).astype(np.int64)
    if np.ptp(ix) <= 1 and np.ptp(iy) <= 1:  # at most 2 x 2 cells: all touch, one mode
        return np.zeros(len(weights), dtype=np.intp)
    key = ix * _KEY + iy
    cells, cell_of = np.unique(key, return_inverse=True)
    rows, cols = [], []
    for dx, dy in _NEIGHBOURS:
        target = cells + dx * _KEY + dy
        at = np.searchsorted(cells, target)
        found = (at < len(cells)) & (cells[np.minimum(at, len(cells) - 1)] == target)
        rows.append(np.flatnonzero(found))
        cols.append(at[found])
    r, c = np.concatenate(rows), np.concatenate(cols)
    graph = coo_matrix((np.ones(len(r)), (r, c)), shape=(len(cells), len(cells)))
    n_modes, cell_label = connected_components(graph, directed=False)
    labels = cell_label[cell_of]
    mass = np.bincount(labels, weights=weights, minlength=n_modes)
    rank = np.empty(n_modes, dtype=np.intp)
    rank[np.argsort(-mass, kind="stable")] = np.arange(n_modes)
    return rank[labels]
