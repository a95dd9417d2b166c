"""Modes of a particle cloud (`filtering.modes.mode_labels`) against a brute-force oracle."""

from __future__ import annotations

import numpy as np
import pytest

from rafostrack.filtering import modes as clusters
from rafostrack.filtering.modes import mode_labels
from rafostrack.model.geodesy import local_offsets_km

LINK_KM = 15.0


def oracle_modes(lat: np.ndarray, lon: np.ndarray, weights: np.ndarray, link_km: float) -> np.ndarray:
    """Modes by definition: particles whose cells (side `link_km`, in the tangent plane of
    the heaviest particle) touch, directly or through other occupied cells, share a mode;
    found by a breadth-first search over every pair of occupied cells; modes ranked by
    mass (ties: the mode whose first cell in (ix, iy) order comes first)."""
    ref = int(np.argmax(weights))
    east, north = local_offsets_km(lat, lon, lat[ref], lon[ref])
    cell = [(int(np.floor(e / link_km)), int(np.floor(n / link_km))) for e, n in zip(east, north, strict=True)]
    cells = sorted(set(cell))
    component: dict[tuple[int, int], int] = {}
    for start in cells:
        if start in component:
            continue
        component[start] = number = len(set(component.values()))
        queue = [start]
        while queue:
            cx, cy = queue.pop()
            for other in cells:
                if other not in component and abs(other[0] - cx) <= 1 and abs(other[1] - cy) <= 1:
                    component[other] = number
                    queue.append(other)
    labels = np.array([component[c] for c in cell])
    mass = np.bincount(labels, weights=weights)
    rank = np.empty(len(mass), dtype=np.intp)
    rank[np.argsort(-mass, kind="stable")] = np.arange(len(mass))
    return rank[labels]


@pytest.mark.parametrize("cells_per_particle", [0, 10**9], ids=["sorted", "dense"])
@pytest.mark.parametrize("seed", range(40))
def test_modes_match_the_oracle(seed: int, cells_per_particle: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """Clouds of 1-4 blobs, compact to spread over many cells, equal and random weights;
    components found by sorting the cells and on a dense grid of them."""
    monkeypatch.setattr(clusters, "_DENSE_CELLS_PER_PARTICLE", cells_per_particle)
    rng = np.random.default_rng(seed)
    n, k = int(rng.integers(1, 300)), int(rng.integers(1, 5))
    centre = rng.normal(0.0, rng.uniform(0.05, 1.5), (k, 2))
    blob = rng.integers(0, k, n)
    lat = -55.0 + centre[blob, 0] + rng.normal(0.0, rng.uniform(0.01, 0.3), n)
    lon = 30.0 + centre[blob, 1] + rng.normal(0.0, rng.uniform(0.01, 0.3), n)
    weights = rng.random(n) if seed % 2 else np.ones(n)
    np.testing.assert_array_equal(mode_labels(lat, lon, weights, LINK_KM), oracle_modes(lat, lon, weights, LINK_KM))


def test_a_mirror_pair_is_two_modes_and_a_bridge_joins_them() -> None:
    """Two clouds 100 km apart are two modes, the heavier first; a line of particles
    between them, closer than a cell apart, makes them one."""
    rng = np.random.default_rng(3)
    lat = np.concatenate([rng.normal(-55.0, 0.02, 200), rng.normal(-55.9, 0.02, 100)])
    lon = np.full(300, 30.0) + rng.normal(0.0, 0.02, 300)
    labels = mode_labels(lat, lon, np.ones(300), LINK_KM)
    assert set(labels[:200]) == {0} and set(labels[200:]) == {1}
    bridge = np.linspace(-55.0, -55.9, 30)
    joined = mode_labels(np.concatenate([lat, bridge]), np.concatenate([lon, np.full(30, 30.0)]), np.ones(330), LINK_KM)
    assert set(joined) == {0}
