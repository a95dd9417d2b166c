"""The paper's two ways of putting a context grid's CF into a particle filter (section II-C).

Naive (the paper's experiment A): every update multiplies each particle's weight by the CF
of the cell it is in, w_t^i = eta p(z_t | x_t^i) CF(x_t^i) (eq. 14 at every step). Correct
only if the target enters a new area at every step; otherwise the same context is counted
again and again ("data incest"), which biases the filter out of wide regions of CF < 1.

Cell entry (the paper's CD update rule, derived from the factorisation of eq. 16): the CF
of an area enters the posterior once, when the path enters it,
    p(x_1:t | z_1:t, eps) = eta prod_t p(z_t | x_t) p(x_t | x_t-1) prod_{entries k} CF_k,
so a particle's weight is multiplied by CF(x_t) only at a step where it entered a new area
(and an observation was made; without one, the particle is resampled by CF instead,
`resample_by_cf`). A move between two filter steps is taken along the straight segment
from x_t-1 to x_t, sampled at half a cell: every change of area along it is an entry, and
the move's factor is the product of the CFs of the cells entered. For the paper's small
steps (a fraction of a cell) that is the paper's rule exactly (the cell before vs the cell
after); for a long step (a float's multi-day gap is one motion step) it also counts the
areas crossed on the way, so a particle cannot jump over a forbidden ridge in one step.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .grid import OUTSIDE, ContextGrid

_MAX_SAMPLES = 2048  # samples along one move (a move crossing more cells is sampled coarser)
_CHUNK_ELEMENTS = 1 << 22  # particles x samples handled at once


def _log(cf: NDArray[np.float64]) -> NDArray[np.float64]:
    with np.errstate(divide="ignore"):
        return np.log(cf)


def naive_log_factor(grid: ContextGrid, x: ArrayLike, y: ArrayLike) -> NDArray[np.float64]:
    """log CF(x_t) for every particle: the naive rule's factor at every step."""
    return _log(grid.cf_at(x, y))


def _unwrapped(grid: ContextGrid, x0: NDArray, x1: NDArray) -> NDArray:
    """x1 moved by whole periods to lie within half a period of x0 (longitudes)."""
    if grid.wrap_x is None:
        return x1
    period = grid.wrap_x
    return x0 + np.mod(x1 - x0 + 0.5 * period, period) - 0.5 * period


def entry_log_factor(
    grid: ContextGrid, x0: ArrayLike, y0: ArrayLike, x1: ArrayLike, y1: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """log of the product of CF over the areas entered along each particle's straight move
    from (x0, y0) to (x1, y1) (module docstring), and whether it entered any new area."""
    x0, y0 = np.asarray(x0, dtype=float), np.asarray(y0, dtype=float)
    x1, y1 = np.asarray(x1, dtype=float), np.asarray(y1, dtype=float)
    x1 = _unwrapped(grid, x0, x1)
    n = len(x0)
    steps_x = np.abs(x1 - x0) / grid.dx
    steps_y = np.abs(y1 - y0) / grid.dy
    longest = float(np.max(np.maximum(steps_x, steps_y))) if n else 0.0
    n_samples = int(min(max(np.ceil(2.0 * longest), 1), _MAX_SAMPLES))
    frac = np.linspace(0.0, 1.0, n_samples + 1)
    log_factor = np.zeros(n)
    entered = np.zeros(n, dtype=bool)
    chunk = max(1, _CHUNK_ELEMENTS // (n_samples + 1))
    for start in range(0, n, chunk):
        part = slice(start, start + chunk)
        xs = x0[part, None] + frac[None, :] * (x1 - x0)[part, None]
        ys = y0[part, None] + frac[None, :] * (y1 - y0)[part, None]
        row, col, inside = grid.cell_of(xs, ys)
        area = np.where(inside, grid.area[row, col], OUTSIDE)
        new = area[:, 1:] != area[:, :-1]
        cf = np.where(inside[:, 1:], grid.cf[row[:, 1:], col[:, 1:]], grid.outside_cf)
        log_factor[part] = np.where(new, _log(cf), 0.0).sum(axis=1)
        entered[part] = new.any(axis=1)
    return log_factor, entered


def resample_by_cf(weights: ArrayLike, cf: ArrayLike, rng: np.random.Generator) -> tuple[NDArray[np.intp], bool]:
    """The paper's 'resample the particle by its CF' (a new area entered, no observation):
    particle i survives with probability g_i = CF_i (g = 1 for particles that entered no new
    area); each one that does not is replaced by a copy of particle j drawn with probability
    proportional to W_j g_j, keeping the weight of the slot it fills. Then the expected
    weighted count of particle i is W_i g_i + (sum_k W_k (1 - g_k)) W_i g_i / G = W_i g_i / G
    (G = sum_k W_k g_k, and G + sum_k W_k (1 - g_k) = 1): the cloud represents the weights
    multiplied by CF, while particles that entered no new area are left alone.

    Returns the ancestor index of every slot and False when no particle could survive
    (G = 0: then nothing is changed)."""
    w = np.asarray(weights, dtype=float)
    g = np.asarray(cf, dtype=float)
    n = len(w)
    target = w * g
    total = float(target.sum())
    if total <= 0:
        return np.arange(n), False
    killed = np.flatnonzero(rng.random(n) >= g)
    index = np.arange(n)
    if len(killed):
        cumulative = np.cumsum(target / total)
        cumulative[-1] = 1.0
        index[killed] = np.searchsorted(cumulative, rng.random(len(killed)), side="right")
    return index, True
