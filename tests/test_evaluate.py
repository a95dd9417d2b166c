"""Scores against simulated truth: labels, their reliability, confidently wrong positions."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from rafostrack.domain import ArrivalRecord, Window
from rafostrack.sim.evaluate import (
    association_accuracy,
    confidently_wrong,
    label_reliability,
    label_scores,
    position_errors_km,
)

T0 = np.datetime64("2010-01-01T00:00:00")


def _record(truth: list[list[str | None]]) -> ArrivalRecord:
    windows = tuple(
        Window(T0 + np.timedelta64(k, "D"), np.arange(1.0, len(labels) + 1) * 100.0, tuple(labels))
        for k, labels in enumerate(truth)
    )
    return ArrivalRecord("f", None, windows)  # type: ignore[arg-type]


def _labels(beacons: list[str | None], probs: list[float]) -> pd.DataFrame:
    return pd.DataFrame({"beacon_id": pd.array(beacons, dtype=object), "prob": probs})


def test_label_scores_mark_each_label_right_or_wrong_in_output_order() -> None:
    record = _record([["A", None], ["B"], [None, "A", "B"]])
    labels = _labels(["A", "B", "B", None, "A", "A"], [0.99, 0.6, 0.95, 0.7, 0.999, 0.8])
    scores = label_scores(labels, record)
    assert scores["right"].tolist() == [True, False, True, True, True, False]
    assert scores["clutter"].tolist() == [False, False, False, True, False, False]
    assert association_accuracy(labels, record) == pytest.approx(4 / 6)


def test_label_scores_refuse_a_label_table_of_another_record() -> None:
    with pytest.raises(ValueError, match="3 labels for 2 stored TOAs"):
        label_scores(_labels(["A", "A", "A"], [1.0, 1.0, 1.0]), _record([["A", None]]))


def test_label_reliability_counts_each_bin_by_brute_force() -> None:
    rng = np.random.default_rng(3)
    prob = np.concatenate([rng.uniform(0.3, 1.0, 400), [0.5, 0.9, 0.99, 1.0]])  # edges fall in the bin below
    right = rng.random(len(prob)) < prob
    scores = pd.DataFrame({"prob": prob, "right": right, "clutter": np.zeros(len(prob), dtype=bool)})
    table = label_reliability(scores, bins=(0.0, 0.5, 0.9, 0.99, 1.0))
    assert table["labels"].sum() == len(prob)
    for row, lo, hi in zip(table.itertuples(), (0.0, 0.5, 0.9, 0.99), (0.5, 0.9, 0.99, 1.0), strict=True):
        inside = [(p, r) for p, r in zip(prob, right, strict=True) if lo < p <= hi or (lo == 0.0 and p == 0.0)]
        assert row.labels == len(inside)
        assert row.wrong == sum(1 for _, r in inside if not r)
        assert row.expected_wrong == pytest.approx(sum(1.0 - p for p, _ in inside))
        assert row.right == pytest.approx(np.mean([r for _, r in inside]))
        assert row.mean_prob == pytest.approx(np.mean([p for p, _ in inside]))


def test_calibrated_labels_have_as_many_wrong_as_expected_and_overconfident_ones_more() -> None:
    rng = np.random.default_rng(7)
    prob = rng.uniform(0.9, 1.0, 20000)
    calibrated = pd.DataFrame({"prob": prob, "right": rng.random(len(prob)) < prob})
    table = label_reliability(calibrated, bins=(0.0, 0.9, 1.0)).iloc[1]
    # Expected wrong ~ 1000, Poisson sd ~ 32: within 4 sd.
    assert abs(table["wrong"] - table["expected_wrong"]) < 4 * np.sqrt(table["expected_wrong"])
    overconfident = calibrated.assign(right=rng.random(len(prob)) < 2 * prob - 1)  # twice the error rate
    table = label_reliability(overconfident, bins=(0.0, 0.9, 1.0)).iloc[1]
    assert table["wrong"] > table["expected_wrong"] + 8 * np.sqrt(table["expected_wrong"])


def test_an_empty_bin_is_reported_empty() -> None:
    scores = pd.DataFrame({"prob": [0.95], "right": [True]})
    table = label_reliability(scores, bins=(0.0, 0.5, 1.0))
    assert table["labels"].tolist() == [0, 1]
    assert np.isnan(table["right"].iloc[0]) and table["wrong"].iloc[0] == 0


def test_confidently_wrong_needs_a_large_error_and_an_sd_under_half_of_it() -> None:
    error = np.array([10.0, 31.0, 31.0, 80.0, 80.0, 29.0])
    sd = np.array([1.0, 15.0, 16.0, 39.0, 41.0, 1.0])
    assert confidently_wrong(error, sd).tolist() == [False, True, False, True, False, False]
    assert confidently_wrong(error, sd, min_error_km=5.0).tolist() == [True, True, False, True, False, True]


def test_position_errors_are_geodesic_distances_at_the_same_times() -> None:
    geodesic = pytest.importorskip("geographiclib.geodesic").Geodesic.WGS84
    times = pd.date_range("2010-01-01", periods=3, freq="D")
    truth = pd.DataFrame({"time": times[::-1], "lat": [-58.0, -57.5, -57.0], "lon": [-100.0, -99.0, -98.0]})
    track = pd.DataFrame({"time": times, "lat": [-57.1, -57.5, -58.3], "lon": [-98.2, -99.5, -100.0]})
    true = truth.set_index("time").loc[times]
    expected = [
        geodesic.Inverse(a, b, c, d)["s12"] / 1e3
        for a, b, c, d in zip(track["lat"], track["lon"], true["lat"], true["lon"], strict=True)
    ]
    np.testing.assert_allclose(position_errors_km(track, truth), expected, atol=0.005)
