"""Scores against simulated truth: association accuracy and position error."""

from __future__ import annotations

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from .domain import ArrivalRecord
from .geodesy import local_offsets_km, range_m


def true_labels(record: ArrivalRecord) -> list[str | None]:
    """The record's known labels, one per stored TOA in output order (window, rank)."""
    return [label for window in record.windows for label in (window.beacon_id or (None,) * window.n_signals)]


def association_accuracy(labels: pd.DataFrame, record: ArrivalRecord) -> float:
    """Fraction of stored TOAs whose label (beacon or clutter) equals the truth."""
    truth = true_labels(record)
    if len(truth) != len(labels):
        raise ValueError(f"{len(labels)} labels for {len(truth)} stored TOAs")
    if not truth:
        return float("nan")
    estimated = [b if isinstance(b, str) else None for b in labels["beacon_id"]]
    return float(np.mean([a == b for a, b in zip(estimated, truth, strict=True)]))


def position_errors_km(track: pd.DataFrame, truth: pd.DataFrame) -> NDArray[np.float64]:
    """Distance (km) from each track row to the true position at the same time."""
    true = truth.set_index(pd.to_datetime(truth["time"])).loc[pd.to_datetime(track["time"])]
    return (
        range_m(track["lat"].to_numpy(), track["lon"].to_numpy(), true["lat"].to_numpy(), true["lon"].to_numpy()) / 1e3
    )


def rmse_km(track: pd.DataFrame, truth: pd.DataFrame) -> float:
    return float(np.sqrt(np.mean(position_errors_km(track, truth) ** 2)))


def inside_ellipse(track: pd.DataFrame, truth: pd.DataFrame, scale: float) -> NDArray[np.bool_]:
    """Whether each true position lies inside the track's ellipse with semi-axes scaled by
    `scale` (posterior.ELLIPSE_95_SCALE for the 95% ellipse)."""
    true = truth.set_index(pd.to_datetime(truth["time"])).loc[pd.to_datetime(track["time"])]
    east, north = local_offsets_km(true["lat"].to_numpy(), true["lon"].to_numpy(), track["lat"], track["lon"])
    angle = np.radians(track["angle_deg"].to_numpy())  # major axis, clockwise from north
    along = east * np.sin(angle) + north * np.cos(angle)
    across = east * np.cos(angle) - north * np.sin(angle)
    smaj = scale * track["smaj_km"].to_numpy()
    smin = np.maximum(scale * track["smin_km"].to_numpy(), 1e-9)
    return (along / smaj) ** 2 + (across / smin) ** 2 <= 1.0
