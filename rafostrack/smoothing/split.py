"""Windows where the two-filter smoother's filters hold the float in different places: the
data did not keep one cloud on the float there.

Each filter's cloud at a window is a posterior of the float's position given the data on
its side (the forward filter: up to the window; the backward one: from the end fix back to
it). Where both hold the float, their means m_f and m_b differ by their own spreads:
with C_f and C_b their covariances, d^2 = (m_b - m_f)' (C_f + C_b)^-1 (m_b - m_f) is about
chi^2 with 2 degrees of freedom. Beyond `SPLIT_D2` (its 0.999 quantile), and more than
`SPLIT_MIN_KM` apart, one of them lost the float (a mirror position where two sources are
heard, a fast eddy, clutter that fits elsewhere): the join weighs the two by their
evidence and mostly keeps the right one, but not always, and a position it keeps wrongly is
reported with the sd of one filter's cloud, confidently wrong. Such a window is reported
as what it is, two positions: `ambiguous`, both in modes.parquet, and an sd that covers
both (the join's covariance plus (m_b - m_f)(m_b - m_f)' / 4, the spread of two equal
modes about their middle).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..domain import Cloud
from ..errors import Notice, WarningKind
from ..model.geodesy import displace, local_offsets_km

SPLIT_D2 = -2.0 * math.log(1e-3)  # chi^2_2 at 0.999, in closed form: -2 log(1 - p)
SPLIT_MIN_KM = 15.0
WARN_FROM_WINDOWS = 3  # split windows in a record from which a warning names them


@dataclass(frozen=True)
class Split:
    """The two filters' mean positions at a window, apart (module docstring)."""

    forward: tuple[float, float]  # lat, lon
    backward: tuple[float, float]
    distance_km: float
    spread_km2: NDArray[np.float64]  # (2, 2) (m_b - m_f)(m_b - m_f)' / 4


def _mean_cov(cloud: Cloud, lat0: float, lon0: float) -> tuple[NDArray, NDArray]:
    """The cloud's weighted mean and covariance (km, km^2) in the plane about (lat0, lon0)."""
    east, north = local_offsets_km(cloud.lat, cloud.lon, lat0, lon0)
    xy = np.column_stack([east, north])
    w = cloud.weights / cloud.weights.sum()
    mean = np.einsum("p,pk->k", w, xy)
    d = xy - mean
    return mean, np.einsum("p,pi,pj->ij", w, d, d)


def split_of(forward: Cloud, backward: Cloud) -> Split | None:
    """The two filters' clouds at one window as a `Split` when they hold the float apart
    (d^2 > `SPLIT_D2` and more than `SPLIT_MIN_KM`), else None."""
    ref = int(np.argmax(forward.weights))
    lat0, lon0 = float(forward.lat[ref]), float(forward.lon[ref])
    (m_f, c_f), (m_b, c_b) = _mean_cov(forward, lat0, lon0), _mean_cov(backward, lat0, lon0)
    delta = m_b - m_f
    distance = float(np.hypot(*delta))
    if distance <= SPLIT_MIN_KM:
        return None
    if float(delta @ np.linalg.solve(c_f + c_b + 1e-9 * np.eye(2), delta)) <= SPLIT_D2:
        return None
    (f_lat, b_lat), (f_lon, b_lon) = displace(np.full(2, lat0), np.full(2, lon0), np.array([m_f[0], m_b[0]]),
                                              np.array([m_f[1], m_b[1]]))  # fmt: skip
    return Split((float(f_lat), float(f_lon)), (float(b_lat), float(b_lon)), distance, np.outer(delta, delta) / 4.0)


def sides(cloud: Cloud, split: Split) -> NDArray[np.int64]:
    """Per particle of a joined cloud, 0 where it lies nearer the forward filter's mean, 1
    nearer the backward one's (the two modes of a split window)."""
    lat, lon = np.array([split.forward[0], split.backward[0]]), np.array([split.forward[1], split.backward[1]])
    east, north = local_offsets_km(cloud.lat[:, None], cloud.lon[:, None], lat[None, :], lon[None, :])
    return np.argmin(np.hypot(east, north), axis=1).astype(np.int64)


def split_warning(times: NDArray[np.datetime64], splits: list[Split | None]) -> Notice | None:
    """One warning naming the split windows' stretches (dates) and how far apart the filters
    held the float, when there are at least `WARN_FROM_WINDOWS` (None otherwise)."""
    flags = np.array([s is not None for s in splits], dtype=bool)
    if flags.sum() < WARN_FROM_WINDOWS:
        return None
    edges = np.flatnonzero(np.diff(np.concatenate([[0], flags.astype(int), [0]])))
    day = [str(np.datetime64(t, "D")) for t in times]
    stretches = [
        day[a] if b - a == 1 else f"{day[a]} to {day[b - 1]}" for a, b in zip(edges[::2], edges[1::2], strict=True)
    ]
    listed = ", ".join(stretches[:4]) + (f" and {len(stretches) - 4} more" if len(stretches) > 4 else "")
    farthest = max(s.distance_km for s in splits if s is not None)
    return Notice(
        WarningKind.SPLIT_TRACK,
        f"the forward and backward filters held the float apart (up to {farthest:.0f} km) on {int(flags.sum())} "
        f"windows ({listed}): the arrivals did not keep one track there; those windows are marked ambiguous, "
        "both positions in modes.parquet, their sd_km covering both",
    )
