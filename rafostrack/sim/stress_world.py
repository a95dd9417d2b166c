"""The stress generator's world (`rafostrack.sim.stress`): the real source arrays (`Geometry`,
`catalogue`), launch positions among them, and the drift: a meandering zonal jet, coherent
rotating eddies drifting with it, and small-scale OU velocity noise, integrated hourly
(second-order Runge-Kutta). Its physics is the generator's own, not the tracker's model.
"""

from __future__ import annotations

import io
import math
from dataclasses import dataclass
from importlib import resources
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from ..domain import BeaconTable, NaT
from ..model.geodesy import displace, local_offsets_km, range_m

if TYPE_CHECKING:
    from .stress_config import StressConfig

DAY_NS = np.timedelta64(86400, "s").astype("timedelta64[ns]")


@dataclass(frozen=True)
class Geometry:
    """A real array over a period, the window the floats listen in, and its current."""

    name: str
    start: str  # first day of the missions
    window_open_s: float  # window opening, seconds after the day's reference time
    window_s: float
    jet_lat: float  # mean latitude of the jet's core
    jet_speed_km_per_day: float  # core speed (eastward positive)
    sound_speed_m_s: float  # the truth's effective sound speed
    slot_s: float  # the spacing of the transmission schedule's slots (rafostrack/data tables)


GEOMETRIES = {
    # DIMES sources transmit at 01:05, 01:15, ..., 01:45 (every 600 s; US1-6 at 01:06), the
    # Weddell sources at 00:30, 00:35, 00:40, ..., 02:10 (every 300 s; W8a at 00:42).
    "dimes": Geometry("dimes", "2010-03-01", 3600.0, 4200.0, -57.5, 7.0, 1488.0, 600.0),
    "weddell": Geometry("weddell", "2008-04-01", 1500.0, 5000.0, -65.5, -4.0, 1471.0, 300.0),
}


# --------------------------------------------------------------------------------------
# Geometry


def _read_csv(name: str) -> pd.DataFrame:
    text = resources.files("rafostrack").joinpath("data", name).read_text(encoding="utf-8")
    return pd.read_csv(io.StringIO(text), dtype=str, keep_default_na=False)


def catalogue(geometry: Geometry) -> BeaconTable:
    """The array's sources active through the whole period, with catalogue offsets (relative
    to the window's opening) and drifts."""
    start = np.datetime64(geometry.start, "D").astype("datetime64[ns]")
    end = start + 300 * DAY_NS
    if geometry.name == "dimes":
        src = _read_csv("dimes_sound_sources.csv").rename(
            columns={"source_id": "beacon_id", "transmit_offset_s": "offset_s", "deployed": "start"}
        )
        src["end"] = ""
    else:
        src = _read_csv("weddell_sound_sources.csv")
    t0 = pd.to_datetime(src["start"]).to_numpy(dtype="datetime64[ns]")
    t1 = pd.to_datetime(src["end"].replace("", None)).to_numpy(dtype="datetime64[ns]")
    active = (t0 <= start) & (np.isnat(t1) | (t1 >= end))
    src = src[active].reset_index(drop=True)
    n = len(src)
    return BeaconTable(
        beacon_id=src["beacon_id"].to_numpy(dtype=object),
        lat=src["lat"].astype(float).to_numpy(),
        lon=src["lon"].astype(float).to_numpy(),
        offset_s=src["offset_s"].astype(float).to_numpy() - geometry.window_open_s,
        drift_s_per_day=src["drift_s_per_day"].astype(float).to_numpy(),
        start=t0[active],
        end=np.full(n, NaT),
    )


def launch_position(beacons: BeaconTable, rng: np.random.Generator) -> tuple[float, float]:
    """A position with at least 3 sources within 900 km: a random source, then a random
    offset of 100-700 km from it, retried until the condition holds."""
    for _ in range(1000):
        i = rng.integers(len(beacons))
        r, a = rng.uniform(100.0, 700.0), rng.uniform(0.0, 2 * np.pi)
        lat, lon = displace(beacons.lat[i], beacons.lon[i], r * np.cos(a), r * np.sin(a))
        if np.sum(range_m(lat, lon, beacons.lat, beacons.lon) < 900e3) >= 3:
            return float(lat), float(lon)
    raise RuntimeError("no launch position with 3 sources within 900 km")


@dataclass(frozen=True)
class Eddy:
    lat: float
    lon: float
    radius_km: float
    swirl_km_per_day: float  # signed: positive anticlockwise


def _velocity(
    lat: float, lon: float, t_days: float, geometry: Geometry, cfg: StressConfig, eddies: list[Eddy]
) -> NDArray[np.float64]:
    """East/north velocity (km/day) of the field at a position and time."""
    v = np.zeros(2)
    if cfg.jet:
        core = geometry.jet_lat + 1.2 * math.sin(2 * math.pi * (lon / 25.0 - t_days / 120.0))
        v[0] += geometry.jet_speed_km_per_day * math.exp(-(((lat - core) / 1.5) ** 2))
        v[0] += 0.25 * geometry.jet_speed_km_per_day  # a weaker flow everywhere
    for e in eddies:
        drift = 0.3 * t_days * (geometry.jet_speed_km_per_day if cfg.jet else 0.0)
        ex, ny = local_offsets_km(lat, lon, e.lat, e.lon)
        dx, dy = float(ex) - drift, float(ny)
        r = math.hypot(dx, dy)
        if r > 4 * e.radius_km:
            continue
        speed = e.swirl_km_per_day * (r / e.radius_km) * math.exp(0.5 * (1 - (r / e.radius_km) ** 2))
        if r > 0:
            v += speed * np.array([-dy / r, dx / r])
    return v


def simulate_track(
    launch: tuple[float, float], times: NDArray[np.datetime64], geometry: Geometry, cfg: StressConfig,
    rng: np.random.Generator,
) -> tuple[pd.DataFrame, list[Eddy]]:  # fmt: skip
    """Positions at `times` (launch first) integrated hourly through the field."""
    eddies = []
    if cfg.eddies:
        for _ in range(cfg.eddy_count):
            r, a = rng.uniform(0.0, 700.0), rng.uniform(0.0, 2 * np.pi)
            elat, elon = displace(launch[0], launch[1], r * np.cos(a), r * np.sin(a))
            swirl = rng.uniform(*cfg.eddy_swirl_km_per_day) * rng.choice([-1.0, 1.0])
            eddies.append(Eddy(float(elat), float(elon), rng.uniform(*cfg.eddy_radius_km), float(swirl)))
    t0 = times[0]
    total_h = round(float((times[-1] - t0) / np.timedelta64(1, "h")))
    h = 1.0 / 24.0
    a = math.exp(-h / cfg.noise_timescale_days)
    noise = rng.standard_normal((total_h + 1, 2)) * cfg.noise_velocity_km_per_day * math.sqrt(1 - a * a)
    u = rng.standard_normal(2) * cfg.noise_velocity_km_per_day
    lat, lon = launch
    path = np.empty((total_h + 1, 2))
    path[0] = lat, lon
    for k in range(total_h):
        t = k * h
        v1 = _velocity(lat, lon, t, geometry, cfg, eddies) + u
        mlat, mlon = displace(lat, lon, 0.5 * h * v1[0], 0.5 * h * v1[1])
        v2 = _velocity(float(mlat), float(mlon), t + 0.5 * h, geometry, cfg, eddies) + u
        lat, lon = (float(x) for x in displace(lat, lon, h * v2[0], h * v2[1]))
        u = a * u + noise[k]
        path[k + 1] = lat, lon
    hours = np.round((times - t0) / np.timedelta64(1, "h")).astype(int)
    track = pd.DataFrame({"time": times.astype("datetime64[ns]"), "lat": path[hours, 0], "lon": path[hours, 1]})
    return track, eddies
