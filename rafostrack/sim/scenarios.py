"""Mission scenarios to simulate: the real DIMES geometry, and a small synthetic array.

`dimes_scenario` gives the real DIMES sound sources (positions, transmission slots,
deployment dates) and floats (launch and recovery fixes, clock offsets) from the package's
data; `synthetic_scenario` a ring of beacons for fast tests and benchmarks.
"""

from __future__ import annotations

import io
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from .. import sample_path
from ..domain import BeaconTable, FloatInfo, NaT
from ..model.geodesy import displace

ONE_DAY = np.timedelta64(86400, "s").astype("timedelta64[ns]")


def sample_mission_dir() -> Path:
    """The bundled sample mission (DIMES floats 759, 767, 811 with SIMULATED arrivals;
    its README.md says how it was made), installed with the package: `rafostrack.sample_path()`."""
    return sample_path()


def _day(text: str) -> np.datetime64:
    return np.datetime64(text, "D").astype("datetime64[ns]")


def _read_package_csv(name: str) -> pd.DataFrame:
    text = resources.files("rafostrack").joinpath("data", name).read_text(encoding="utf-8")
    return pd.read_csv(io.StringIO(text), dtype=str, keep_default_na=False)


DIMES_FLOATS = ("759", "767", "811")  # the DIMES floats of `dimes_scenario`: rows of data/dimes_floats.csv


def dimes_scenario(
    float_ids: tuple[str, ...] | list[str] = DIMES_FLOATS, window_open_s: float = 3600.0
) -> tuple[BeaconTable, list[FloatInfo]]:
    """The DIMES sound sources and floats (real geometry, deployment dates and clock offsets).

    Source offsets are relative to the float's window, which opens `window_open_s` after
    the day's reference time (00:00Z): offset_s = transmit_offset_s - window_open_s. The
    float ids are "float759" etc. (give "759" or "float759"); window_s = 4200,
    max_signals = 4, windows at 00:00Z.
    """
    src = _read_package_csv("dimes_sound_sources.csv")
    beacons = BeaconTable(
        beacon_id=src["source_id"].to_numpy(dtype=object),
        lat=src["lat"].astype(float).to_numpy(),
        lon=src["lon"].astype(float).to_numpy(),
        offset_s=src["transmit_offset_s"].astype(float).to_numpy() - float(window_open_s),
        drift_s_per_day=src["drift_s_per_day"].astype(float).to_numpy(),
        start=np.array([_day(d) for d in src["deployed"]], dtype="datetime64[ns]"),
        end=np.full(len(src), NaT),
    )
    table = _read_package_csv("dimes_floats.csv").set_index("float")
    floats = []
    for fid in float_ids:
        key = str(fid).removeprefix("float")
        if key not in table.index:
            raise ValueError(f"unknown DIMES float {fid!r}; known: {', '.join(table.index)}")
        row = table.loc[key]
        floats.append(
            FloatInfo(
                float_id=f"float{key}",
                launch_time=_day(row["launch_date"]),
                launch_lat=float(row["launch_lat"]),
                launch_lon=float(row["launch_lon"]),
                end_time=_day(row["recovery_date"]),
                end_lat=float(row["recovery_lat"]),
                end_lon=float(row["recovery_lon"]),
                clock_offset_start_s=float(row["clock_offset_launch_s"]),
                clock_offset_end_s=float(row["clock_offset_recovery_s"]),
                window_s=4200.0,
                max_signals=4,
            )
        )
    return beacons, floats


def synthetic_scenario(
    n_beacons: int = 8,
    days: int = 60,
    rng: np.random.Generator | int | None = None,
    *,
    n_floats: int = 1,
) -> tuple[BeaconTable, list[FloatInfo]]:
    """A small array for tests and benchmarks (deterministic: `rng=None` means seed 0).

    Beacons on a ring of radius 600 km (the array ~1200 km across) around (-58, -90), with
    a random rotation, always active, no drift, transmission offsets spread evenly over
    0..1500 s in a random order. Floats launch within ~50 km of the centre on 2010-01-01
    00:00Z, with an end fix 200-400 km away after `days` days (scaled by days / 60 for
    shorter missions: a float drifts 3-7 km/day, not the 10-20 km/day that 200-400 km in 20
    days would take) and clock offsets within +-2 s; window_s = 4200, max_signals = 4.
    """
    if n_beacons < 1 or n_floats < 1 or days < 1:
        raise ValueError("n_beacons, n_floats and days must be >= 1")
    gen = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(0 if rng is None else rng)
    lat0, lon0, radius_km = -58.0, -90.0, 600.0
    angle = gen.uniform(0, 2 * np.pi) + 2 * np.pi * np.arange(n_beacons) / n_beacons
    blat, blon = displace(np.full(n_beacons, lat0), np.full(n_beacons, lon0), *_polar(radius_km, angle))
    offsets = np.linspace(0.0, 1500.0, n_beacons)[gen.permutation(n_beacons)]
    beacons = BeaconTable(
        beacon_id=np.array([f"B{i + 1}" for i in range(n_beacons)], dtype=object),
        lat=np.round(blat, 4),
        lon=np.round(blon, 4),
        offset_s=np.round(offsets, 2),
        drift_s_per_day=np.zeros(n_beacons),
        start=np.full(n_beacons, NaT),
        end=np.full(n_beacons, NaT),
    )
    launch = _day("2010-01-01")
    floats = []
    for j in range(n_floats):
        la, lo = displace(lat0, lon0, *_polar(gen.uniform(0, 50), gen.uniform(0, 2 * np.pi)))
        ea, eo = displace(la, lo, *_polar(gen.uniform(200, 400) * min(1.0, days / 60), gen.uniform(0, 2 * np.pi)))
        c0, c1 = gen.uniform(-2, 2, 2)
        floats.append(
            FloatInfo(
                float_id=f"sim{j + 1}",
                launch_time=launch,
                launch_lat=round(float(la), 4),
                launch_lon=round(float(lo), 4),
                end_time=launch + ONE_DAY * days,
                end_lat=round(float(ea), 4),
                end_lon=round(float(eo), 4),
                clock_offset_start_s=round(float(c0), 2),
                clock_offset_end_s=round(float(c1), 2),
                window_s=4200.0,
                max_signals=4,
            )
        )
    return beacons, floats


def _polar(r_km: Any, angle: Any) -> tuple[NDArray, NDArray]:
    """East/north components of a displacement of `r_km` at `angle` (radians from east)."""
    return np.asarray(r_km * np.cos(angle)), np.asarray(r_km * np.sin(angle))
