"""The ranked-signal paper's setting: its planar simulation mapped onto rafostrack, target
trajectories, and a seeded runner that scores a method against the truth.

The paper's simulations (section 3.1) live in a unit 2-D plane where an arrival time is a
distance over a speed: 10 beacons, the first 4 signals stored, Pd = 0.7, TOA sd 0.02 (in
units of distance), clutter Poisson(lambda) per window, uniform over the window. rafostrack
works on the WGS84 ellipsoid with a sound speed, so `PaperSetting` maps the plane onto a
geographic box: one paper unit is `unit_km` km east/north of the box centre (a local
equirectangular projection), arrival times are WGS84 ranges over `sound_speed_m_s`, and the
TOA sd is 0.02 units of travel time. Simulation is `rafostrack.sim.simulate.simulate_arrivals`
and tracking `rafostrack.run.method.track_record`: the package's own model, not a copy.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from rafostrack.config import Config, load_config, method_overrides, with_overrides
from rafostrack.domain import ArrivalRecord, BeaconTable, FloatInfo
from rafostrack.model.geodesy import displace, local_offsets_km
from rafostrack.problem import FloatProblem
from rafostrack.run.method import TrackOutput, track_record
from rafostrack.sim.evaluate import position_errors_km
from rafostrack.sim.scenarios import sample_mission_dir
from rafostrack.sim.simulate import simulate_arrivals

T0 = np.datetime64("2010-01-01T00:00:00", "ns")


ONE_DAY = np.timedelta64(86400, "s").astype("timedelta64[ns]")


NaT = np.datetime64("NaT", "ns")


SAMPLES = sample_mission_dir()


CLUTTER_LEVELS = (0.5, 1.0, 2.0, 4.0, 8.0)


LOST_UNITS = 0.1  # a window's position error above this (50 km) counts as the target lost


@dataclass(frozen=True)
class PaperSetting:
    """The paper's simulation setting (section 3.1) on a geographic box near 58 S."""

    unit_km: float = 500.0  # one paper unit of distance
    centre_lat: float = -58.0  # the plane's point (0.5, 0.5)
    centre_lon: float = -90.0
    sound_speed_m_s: float = 1480.0
    sigma_units: float = 0.02  # TOA sd, in units of distance travelled
    p_detect: float = 0.7
    n_beacons: int = 10
    max_signals: int = 4
    window_units: float = 1.5  # > sqrt(2): every arrival from inside the box fits
    beacon_seed: int = 2015  # the beacons' fixed random positions in the unit box
    launch_sd_km: float = 1.0  # the known initial position X_0 (tracker's launch prior)

    @property
    def unit_s(self) -> float:
        """Travel time (s) of one paper unit."""
        return self.unit_km * 1e3 / self.sound_speed_m_s

    @property
    def toa_sigma_s(self) -> float:
        return self.sigma_units * self.unit_s

    @property
    def window_s(self) -> float:
        return round(self.window_units * self.unit_s, 2)

    def to_geo(self, x: NDArray, y: NDArray) -> tuple[NDArray, NDArray]:
        """Plane (units) to (lat, lon): (0.5, 0.5) is the box centre."""
        x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        east, north = (x - 0.5) * self.unit_km, (y - 0.5) * self.unit_km
        return displace(np.full(x.shape, self.centre_lat), np.full(x.shape, self.centre_lon), east, north)

    def to_plane(self, lat: NDArray, lon: NDArray) -> tuple[NDArray, NDArray]:
        """(lat, lon) to plane units (the exact inverse of `to_geo`)."""
        east, north = local_offsets_km(np.asarray(lat), np.asarray(lon), self.centre_lat, self.centre_lon)
        return 0.5 + np.asarray(east) / self.unit_km, 0.5 + np.asarray(north) / self.unit_km

    def beacon_xy(self) -> NDArray[np.float64]:
        """(n_beacons, 2) fixed random beacon positions, uniform in the unit box."""
        return np.random.default_rng(self.beacon_seed).uniform(0.0, 1.0, (self.n_beacons, 2))

    def beacons(self) -> BeaconTable:
        """Always active, transmitting at the window's opening (offset 0), no clock drift."""
        xy = self.beacon_xy()
        lat, lon = self.to_geo(xy[:, 0], xy[:, 1])
        n = self.n_beacons
        return BeaconTable(
            beacon_id=np.array([f"B{i + 1}" for i in range(n)], dtype=object),
            lat=np.asarray(lat, dtype=float),
            lon=np.asarray(lon, dtype=float),
            offset_s=np.zeros(n),
            drift_s_per_day=np.zeros(n),
            start=np.full(n, NaT),
            end=np.full(n, NaT),
        )

    def float_info(self, float_id: str, x0: float, y0: float) -> FloatInfo:
        """A target launched at (x0, y0) at T0, no end fix (the paper has none), no clock error."""
        lat, lon = self.to_geo(np.array([x0]), np.array([y0]))
        return FloatInfo(
            float_id=float_id,
            launch_time=T0,
            launch_lat=float(lat[0]),
            launch_lon=float(lon[0]),
            end_time=NaT,
            end_lat=math.nan,
            end_lon=math.nan,
            clock_offset_start_s=0.0,
            clock_offset_end_s=0.0,
            window_s=self.window_s,
            max_signals=self.max_signals,
        )

    def config(
        self,
        *,
        clutter_rate: float,
        diffusion_km_per_day: float,
        method: str = "exact",
        particles: int = 1000,
        seed: int = 0,
        smooth: bool = True,
    ) -> Config:
        """The tracker's configuration: rafostrack's method with the measurement model known
        (matching the simulation's, so no calibration): the default drift model (integrated
        OU, its velocity sd the target's daily step) and lost-track recovery. (The paper's
        random walk without recovery loses the Fig. 5 spiral at 1000 particles: 170 km RMSE
        on seed 0.)"""
        return with_overrides(
            load_config(),
            model={
                "sound_speed_m_s": self.sound_speed_m_s,
                "toa_sigma_s": self.toa_sigma_s,
                "p_detect": self.p_detect,
                "clutter_rate": float(clutter_rate),
                "multipath_fraction": 0.0,
                "echo_fraction": 0.0,
                "detection_range_km": 0.0,
                "window_s": self.window_s,
                "max_signals": self.max_signals,
            },
            motion={
                "diffusion_km_per_day": float(diffusion_km_per_day),
                "velocity_sd_km_per_day": float(diffusion_km_per_day),
            },
            calibrate={"enabled": False},
            recovery={"enabled": True},
            fixes={"launch_sd_km": self.launch_sd_km, "use_end_fix": False},
            filter={**method_overrides(method), "particles": int(particles), "seed": int(seed)},
            smoother={"enabled": bool(smooth)},
        )

    def describe(self) -> str:
        """The mapping, for REPORT.md."""
        return (
            f"one paper unit = {self.unit_km:g} km (a local east/north plane centred at "
            f"{abs(self.centre_lat):g}°S {abs(self.centre_lon):g}°W); sound speed {self.sound_speed_m_s:g} m/s, "
            f"so one unit of travel takes {self.unit_s:.1f} s; TOA sd 0.02 units = {self.toa_sigma_s:.2f} s "
            f"({self.sigma_units * self.unit_km:g} km); {self.n_beacons} beacons at fixed uniform random positions "
            f"in the unit box (seed {self.beacon_seed}), always on, offset 0; window {self.window_s:g} s "
            f"({self.window_units:g} units, longer than the box diagonal); Pd {self.p_detect:g}; first "
            f"{self.max_signals} signals stored; clutter Poisson(lambda) per window, uniform over the window; "
            f"arrival time = WGS84 range / sound speed (within ~6% of the plane distance at the box's edges; "
            f"simulator and tracker share it); launch position known to {self.launch_sd_km:g} km, no end fix"
        )


def line_xy(days: int, start: tuple[float, float] = (0.15, 0.2), end: tuple[float, float] = (0.85, 0.75)) -> NDArray:
    """A straight line at constant speed (paper Figs. 4a and 6a), shape (days + 1, 2)."""
    f = np.linspace(0.0, 1.0, days + 1)[:, None]
    return (1.0 - f) * np.asarray(start) + f * np.asarray(end)


def spiral_xy(days: int, r_out: float = 0.42, r_in: float = 0.08, turns: float = 2.0) -> NDArray:
    """An inward Archimedean spiral about the box centre at constant speed (paper Fig. 5a)."""
    theta = np.linspace(0.0, 2.0 * np.pi * turns, 20001)
    r = r_out - (r_out - r_in) * theta / theta[-1]
    dense = np.column_stack([0.5 + r * np.cos(theta), 0.5 + r * np.sin(theta)])
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(dense, axis=0).T))])
    s = np.linspace(0.0, arc[-1], days + 1)
    return np.column_stack([np.interp(s, arc, dense[:, 0]), np.interp(s, arc, dense[:, 1])])


@dataclass(frozen=True)
class Scenario:
    """A target with an explicit daily truth track in the paper setting."""

    name: str
    setting: PaperSetting
    xy: NDArray[np.float64]  # (days + 1, 2) plane positions, launch first
    beacons: BeaconTable
    info: FloatInfo
    truth: pd.DataFrame  # time, lat, lon (launch and every window)

    @property
    def days(self) -> int:
        return len(self.xy) - 1

    @property
    def step_km(self) -> float:
        """Mean daily displacement of the truth (km)."""
        return float(np.mean(np.hypot(*np.diff(self.xy, axis=0).T)) * self.setting.unit_km)

    @property
    def diffusion_km_per_day(self) -> float:
        """The tracker's random-walk sd per axis per day: the truth's daily step, so one day's
        true displacement is about one random-walk sd along any axis."""
        return round(self.step_km, 2)

    def simulate(self, config: Config, rng: np.random.Generator) -> ArrivalRecord:
        """Arrivals along the truth by the package's generative model."""
        record, _ = simulate_arrivals(self.beacons, self.info, config.model, self.truth, rng, days=self.days)
        return record

    def config(self, clutter_rate: float, **kwargs: Any) -> Config:
        return self.setting.config(clutter_rate=clutter_rate, diffusion_km_per_day=self.diffusion_km_per_day, **kwargs)


def make_scenario(shape: str, days: int, setting: PaperSetting | None = None) -> Scenario:
    """`shape` "line" (paper Fig. 4 / 6) or "spiral" (Fig. 5)."""
    setting = setting or PaperSetting()
    if shape == "line":
        xy = line_xy(days)
    elif shape == "spiral":
        xy = spiral_xy(days)
    else:
        raise ValueError(f"unknown trajectory {shape!r}: expected line or spiral")
    lat, lon = setting.to_geo(xy[:, 0], xy[:, 1])
    truth = pd.DataFrame({"time": T0 + ONE_DAY * np.arange(days + 1), "lat": lat, "lon": lon})
    info = setting.float_info(shape, xy[0, 0], xy[0, 1])
    return Scenario(shape, setting, xy, setting.beacons(), info, truth)


def line_record(
    days: int, clutter_rate: float, particles: int, seed: int, data_seed: int, *data_keys: float
) -> tuple[Scenario, Config, ArrivalRecord]:
    """The line target of `days` days, the tracker's configuration (`particles`, `seed`) and
    a record simulated at `clutter_rate` with the generator `data_rng(data_seed, *data_keys)`."""
    scenario = make_scenario("line", days)
    config = scenario.config(clutter_rate, particles=particles, seed=seed)
    return scenario, config, scenario.simulate(config, data_rng(data_seed, *data_keys))


def data_rng(seed: int, *keys: float) -> np.random.Generator:
    """The simulation generator of one (seed, case...) run, independent of run order."""
    return np.random.default_rng([int(seed), *(round(k * 1000) for k in keys)])


@dataclass(frozen=True)
class MethodRun:
    """Scores of one method on one simulated record (filtered and smoothed)."""

    method: str
    output: TrackOutput
    sq_err_filtered: NDArray[np.float64]  # per window, plane units^2
    sq_err_smoothed: NDArray[np.float64]
    seconds: float


def run_method(
    scenario: Scenario, record: ArrivalRecord, config: Config, method: str, *, smooth: bool = True
) -> MethodRun:
    """Track `record` with `method` (filtered, and smoothed when `smooth`) and score both
    against the scenario's truth in squared plane units."""
    cfg = with_overrides(config, filter=method_overrides(method), smoother={"enabled": smooth})
    out = track_record(FloatProblem(scenario.beacons, scenario.info, cfg), record, also_filtered=True)
    unit2 = scenario.setting.unit_km**2
    assert out.filtered is not None  # asked for with also_filtered
    err_f = position_errors_km(out.filtered.track, scenario.truth) ** 2 / unit2
    err_s = position_errors_km(out.estimate.track, scenario.truth) ** 2 / unit2 if smooth else err_f
    return MethodRun(method, out, err_f, err_s, out.seconds.filter_s + out.seconds.smoother_s)


def method_task(task: tuple[Scenario, ArrivalRecord, Config, str]) -> MethodRun:
    """`run_method(*task)`, for `pmap`."""
    return run_method(*task)


def true_signal_counts(record: ArrivalRecord) -> NDArray[np.int64]:
    """Stored TOAs per window that came from a beacon (by the record's known labels)."""
    return np.array([sum(b is not None for b in (w.beacon_id or ())) for w in record.windows], dtype=np.int64)


def day_text(t: np.datetime64) -> str:
    return str(np.datetime_as_string(np.datetime64(t).astype("datetime64[D]")))


def span_text(spans: Sequence[tuple[np.datetime64, np.datetime64]], limit: int = 12) -> str:
    """'2009-03-01..2009-03-04, 2009-05-02' (a single day once); 'none' when empty."""
    if not spans:
        return "none"
    parts = [day_text(a) if a == b else f"{day_text(a)}..{day_text(b)}" for a, b in spans[:limit]]
    more = f" and {len(spans) - limit} more" if len(spans) > limit else ""
    return ", ".join(parts) + more
