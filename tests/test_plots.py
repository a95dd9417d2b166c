"""Plots: three valid PNGs written atomically, also for degenerate inputs."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from rafostrack.config import load_config
from rafostrack.domain import BeaconTable, FloatInfo
from rafostrack.estimates import MODE_COLUMNS, Estimate
from rafostrack.model import predicted_arrivals
from rafostrack.plots import beacon_colors, write_plots

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
NAMES = ["track.png", "arrivals.png", "uncertainty.png"]
T0 = np.datetime64("2010-01-01T00:00:00", "ns")
NAT = np.datetime64("NaT", "ns")


@pytest.fixture(scope="module")
def model():
    return load_config().model


@pytest.fixture(scope="module")
def beacons() -> BeaconTable:
    return BeaconTable(
        beacon_id=np.array(["S1", "S2", "S3", "S4"], dtype=object),
        lat=np.array([-56.0, -60.0, -57.5, -61.0]),
        lon=np.array([-100.0, -98.0, -88.0, -86.0]),
        offset_s=np.zeros(4),
        drift_s_per_day=np.array([0.0, 0.01, 0.0, -0.02]),
        start=np.array([NAT, NAT, NAT, T0 + np.timedelta64(10, "D")]),
        end=np.array([NAT, NAT, NAT, NAT]),
    )


@pytest.fixture(scope="module")
def info() -> FloatInfo:
    return FloatInfo(
        float_id="F01",
        launch_time=T0,
        launch_lat=-58.0,
        launch_lon=-96.0,
        end_time=T0 + np.timedelta64(29, "D"),
        end_lat=-58.6,
        end_lon=-91.5,
        clock_offset_start_s=0.0,
        clock_offset_end_s=0.0,
        window_s=4200.0,
        max_signals=4,
    )


def make_track(n: int, *, sd: float | None = 5.0) -> pd.DataFrame:
    k = np.arange(n)
    return pd.DataFrame(
        {
            "float_id": "F01",
            "time": T0 + k * np.timedelta64(1, "D"),
            "lat": -58.0 - 0.02 * k,
            "lon": -96.0 + 0.15 * k,
            "sd_km": np.full(n, np.nan) if sd is None else sd + 0.3 * k,
            "ess": np.linspace(900.0, 300.0, n),
            "n_signals": (k % 5).astype(int),
            "loglik": -10.0 - k,
        }
    )


def make_labels(track: pd.DataFrame, beacons: BeaconTable, info: FloatInfo, model) -> pd.DataFrame:
    """One TOA per active beacon per window at the predicted time, plus one clutter TOA."""
    pred = predicted_arrivals(track.time.to_numpy(), track.lat.to_numpy(), track.lon.to_numpy(), beacons, info, model)
    rows = []
    for k, t in enumerate(track.time):
        toas = [(pred[k, j], beacons.beacon_id[j], 0.9) for j in range(len(beacons)) if np.isfinite(pred[k, j])]
        toas.append((100.0 + 37.0 * k, None, 0.6))
        for rank, (toa, bid, p) in enumerate(sorted(toas, key=lambda r: r[0]), start=1):
            rows.append(
                {
                    "float_id": "F01",
                    "time": t,
                    "rank": rank,
                    "toa_s": toa,
                    "beacon_id": bid,
                    "prob": p,
                    "p_clutter": p if bid is None else 1 - p,
                }
            )
    return pd.DataFrame(rows)


def empty_labels() -> pd.DataFrame:
    return pd.DataFrame(
        {
            "float_id": pd.Series([], dtype=object),
            "time": pd.Series([], dtype="datetime64[ns]"),
            "rank": pd.Series([], dtype=int),
            "toa_s": pd.Series([], dtype=float),
            "beacon_id": pd.Series([], dtype=object),
            "prob": pd.Series([], dtype=float),
            "p_clutter": pd.Series([], dtype=float),
        }
    )


def assert_pngs(outdir: Path, paths: list[Path]) -> None:
    assert [p.name for p in paths] == NAMES
    for p in paths:
        assert p.parent == outdir and p.is_file()
        data = p.read_bytes()
        assert data[:8] == PNG_MAGIC
        assert len(data) > 10_000
        width, height = struct.unpack(">II", data[16:24])  # IHDR
        assert (width, height) == (1200, 720)
    assert sorted(f.name for f in outdir.iterdir()) == sorted(NAMES)  # no temporary files left


def _estimate(track: pd.DataFrame, labels: pd.DataFrame) -> Estimate:
    return Estimate("smoothed", track, labels, pd.DataFrame(columns=list(MODE_COLUMNS)))


def test_write_plots_full(tmp_path, beacons, info, model):
    track = make_track(30)
    labels = make_labels(track, beacons, info, model)
    truth = track[["time", "lat", "lon"]].assign(lat=track.lat + 0.05)
    paths = write_plots(tmp_path / "out", _estimate(track, labels), beacons, info, model, truth=truth)
    assert_pngs(tmp_path / "out", paths)


@pytest.mark.filterwarnings("error")
def test_write_plots_empty_labels(tmp_path, beacons, info, model):
    paths = write_plots(tmp_path, _estimate(make_track(30), empty_labels()), beacons, info, model)
    assert_pngs(tmp_path, paths)


@pytest.mark.filterwarnings("error")
def test_write_plots_single_window_all_clutter_nan_sd(tmp_path, beacons, info, model):
    track = make_track(1, sd=None)
    labels = make_labels(track, beacons, info, model).assign(beacon_id=None, prob=0.7)
    labels.loc[0, "beacon_id"] = np.nan  # clutter may also come back as NaN from a file
    paths = write_plots(tmp_path, _estimate(track, labels), beacons, info, model)
    assert_pngs(tmp_path, paths)


def test_write_plots_empty_track_overwrites(tmp_path, beacons, info, model):
    no_end = FloatInfo(**{**info.__dict__, "end_time": NAT, "end_lat": np.nan, "end_lon": np.nan})
    for name in NAMES:  # stale output from an earlier run is replaced
        (tmp_path / name).write_bytes(b"old")
    paths = write_plots(tmp_path, _estimate(make_track(0), empty_labels()), beacons, no_end, model)
    assert_pngs(tmp_path, paths)


def test_beacon_colors_distinct_and_not_grey():
    colors = beacon_colors([f"B{i}" for i in range(18)])
    rgb = {c[:3] for c in colors.values()}
    assert len(rgb) == 18
    assert all(not (r == g == b) for r, g, b in rgb)
