"""The update rules: the factor of a move, and resampling by CF."""

from __future__ import annotations

import numpy as np

from rafostrack.context.grid import ContextGrid
from rafostrack.context.rules import entry_log_factor, naive_log_factor, resample_by_cf

# Columns: x in [0, 10) CF 1, [10, 12) CF 0 (a thin ridge), [12, 20) CF 1, [20, 30) CF 0.5.
CF = np.concatenate([np.ones(10), np.zeros(2), np.ones(8), np.full(10, 0.5)])[None, :].repeat(4, axis=0)
GRID = ContextGrid(0.0, 0.0, 1.0, 1.0, CF)


def test_entry_factor_counts_each_area_entered_along_the_move():
    x0 = np.array([1.0, 1.0, 14.0, 21.0, 25.0, 1.0])
    x1 = np.array([5.0, 15.0, 22.0, 28.0, 14.0, 1.5])
    y = np.full(6, 2.0)
    log_f, entered = entry_log_factor(GRID, x0, y, x1, y)
    assert log_f[0] == 0.0 and not entered[0]  # within one area
    assert log_f[1] == -np.inf and entered[1]  # both ends allowed, the ridge crossed on the way
    assert log_f[2] == np.log(0.5)  # into the CF 0.5 area, once
    assert log_f[3] == 0.0  # moving within it costs nothing (the naive rule would charge 0.5)
    assert log_f[4] == 0.0  # back into CF 1
    assert naive_log_factor(GRID, x1[3:4], y[3:4])[0] == np.log(0.5)


def test_long_moves_across_the_grid_edge_and_the_dateline():
    grid = ContextGrid(170.0, 0.0, 1.0, 1.0, np.array([[1.0] * 9 + [0.0] + [1.0] * 10]), wrap_x=360.0)
    log_f, _ = entry_log_factor(grid, np.array([175.0, 175.0]), np.array([0.5, 0.5]),
                                np.array([-172.0, 178.5]), np.array([0.5, 0.5]))  # fmt: skip
    assert log_f[0] == -np.inf  # 175 E to 172 W crosses the CF-0 column at 179 E
    assert log_f[1] == 0.0


def test_resample_by_cf_represents_weights_times_cf():
    rng = np.random.default_rng(0)
    w = rng.random(6)
    w /= w.sum()
    g = np.array([1.0, 0.5, 0.0, 1.0, 0.2, 1.0])
    target = w * g / (w * g).sum()
    counts = np.zeros(6)
    reps = 20000
    for _ in range(reps):
        index, ok = resample_by_cf(w, g, rng)
        assert ok
        np.add.at(counts, index, w)  # each slot keeps its weight, holds particle index[slot]
        assert np.all(index[g == 1.0] == np.flatnonzero(g == 1.0))  # untouched
    np.testing.assert_allclose(counts / reps, target, atol=0.01)
    index, ok = resample_by_cf(w, np.zeros(6), rng)
    assert not ok and np.array_equal(index, np.arange(6))
