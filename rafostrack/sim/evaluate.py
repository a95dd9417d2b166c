"""Scores against simulated truth: association accuracy, how well the label probabilities
are calibrated, position error and ellipse coverage, and answers that are confidently wrong."""

from __future__ import annotations

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

from ..domain import ArrivalRecord
from ..model.geodesy import local_offsets_km, range_m
from ..summaries.estimates import Estimate
from .simulate import SimulatedFloat


def true_labels(record: ArrivalRecord) -> list[str | None]:
    """The record's known labels, one per stored TOA in output order (window, rank)."""
    return [label for window in record.windows for label in (window.beacon_id or (None,) * window.n_signals)]


def label_scores(labels: pd.DataFrame, record: ArrivalRecord) -> pd.DataFrame:
    """Per stored TOA (output order): the probability given to its label (`prob`), whether
    the label (beacon or clutter) equals the truth (`right`), and whether it says clutter."""
    truth = true_labels(record)
    if len(truth) != len(labels):
        raise ValueError(f"{len(labels)} labels for {len(truth)} stored TOAs")
    estimated = [b if isinstance(b, str) else None for b in labels["beacon_id"]]
    return pd.DataFrame(
        {
            "prob": labels["prob"].to_numpy(dtype=float),
            "right": np.array([a == b for a, b in zip(estimated, truth, strict=True)], dtype=bool),
            "clutter": np.array([b is None for b in estimated], dtype=bool),
        }
    )


def association_accuracy(labels: pd.DataFrame, record: ArrivalRecord) -> float:
    """Fraction of stored TOAs whose label (beacon or clutter) equals the truth."""
    right = label_scores(labels, record)["right"]
    return float(right.mean()) if len(right) else float("nan")


# Bins of the probability a label is given: most labels are given with more than 0.99, so
# the bins resolve the top, where a confidently wrong label lives.
RELIABILITY_BINS = (0.0, 0.5, 0.7, 0.9, 0.99, 0.999, 1.0)


def label_reliability(scores: pd.DataFrame, bins: tuple[float, ...] = RELIABILITY_BINS) -> pd.DataFrame:
    """Reliability of label probabilities (`label_scores` rows, of one float or many): per
    bin (lo, hi] of the probability given, the labels in it, the fraction right, the mean
    probability given, and the wrong labels beside the number expected, the sum of
    1 - prob. Calibrated labels have `right` close to `mean_prob` in every bin; a bin with
    many more wrong than expected holds overconfident labels."""
    edges = np.asarray(bins, dtype=float)
    which = np.clip(np.searchsorted(edges, scores["prob"].to_numpy(), side="left") - 1, 0, len(edges) - 2)
    rows = []
    for k in range(len(edges) - 1):
        inside = scores[which == k]
        rows.append(
            {
                "bin": f"({edges[k]:g}, {edges[k + 1]:g}]",
                "labels": len(inside),
                "right": float(inside["right"].mean()) if len(inside) else float("nan"),
                "mean_prob": float(inside["prob"].mean()) if len(inside) else float("nan"),
                "wrong": int((~inside["right"]).sum()),
                "expected_wrong": float((1.0 - inside["prob"]).sum()),
            }
        )
    return pd.DataFrame(rows)


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


def confidently_wrong(error_km: ArrayLike, sd_km: ArrayLike, min_error_km: float = 30.0) -> NDArray[np.bool_]:
    """Windows whose position is more than `min_error_km` off while the reported sd_km is
    under half the error: wrong, and saying otherwise (the worst answer a tracker gives)."""
    error, sd = np.asarray(error_km, dtype=float), np.asarray(sd_km, dtype=float)
    return (error > min_error_km) & (sd < error / 2.0)


def truth_estimate(sim: SimulatedFloat) -> Estimate:
    """A 'first pass' made of a simulated float's truth: the true track at every window,
    every stored TOA labelled with its true source at probability 1 (clutter: no beacon)."""
    labels = pd.DataFrame(
        [
            (w.time, j + 1, t, b, 1.0 if b is not None else 0.0)
            for w in sim.record.windows
            for j, (t, b) in enumerate(zip(w.toa_s, w.beacon_id or (None,) * w.n_signals, strict=True))
        ],
        columns=["time", "rank", "toa_s", "beacon_id", "prob"],
    )
    times = np.array([w.time for w in sim.record.windows], dtype="datetime64[ns]")
    at = sim.truth.set_index("time").loc[times]
    track = pd.DataFrame({"time": times, "lat": at["lat"].to_numpy(), "lon": at["lon"].to_numpy(), "ambiguous": False})
    return Estimate("smoothed", track, labels, pd.DataFrame())
