"""The domain: beacons, floats, listening windows, position fixes and particle clouds.

Plain data, no I/O and no model: readers (`rafostrack.io`) build these, the model,
filter and smoother consume them. Times are UTC `numpy.datetime64[ns]`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

NaT = np.datetime64("NaT", "ns")
SECONDS_PER_DAY = 86400.0


def days_between(start: np.datetime64, end: np.datetime64) -> float:
    """(end - start) in days, as a float."""
    return float(elapsed_days(np.asarray(end), start))


def elapsed_days(times: NDArray[np.datetime64], epoch: NDArray[np.datetime64] | np.datetime64) -> NDArray[np.float64]:
    """(times - epoch) in days, elementwise (via seconds, as float64)."""
    seconds: NDArray[np.float64] = np.asarray(times - epoch) / np.timedelta64(1, "s")  # type: ignore[operator]
    return seconds / SECONDS_PER_DAY


@dataclass(frozen=True)
class BeaconTable:
    """Moored sound sources: position, transmission offset, clock drift, active period."""

    beacon_id: NDArray[np.object_]
    lat: NDArray[np.float64]
    lon: NDArray[np.float64]
    offset_s: NDArray[np.float64]
    drift_s_per_day: NDArray[np.float64]
    start: NDArray[np.datetime64]
    end: NDArray[np.datetime64]
    # Per-beacon model values (NaN, or None for all, = the configuration's): effective
    # sound speed along the beacon's paths, peak detection probability, and the range at
    # which it has halved (see `model.measurement.detection_prob`). Set by calibration.
    sound_speed_m_s: NDArray[np.float64] | None = None
    p_detect: NDArray[np.float64] | None = None
    detection_range_km: NDArray[np.float64] | None = None
    # Where each row was read (file, and line per row: header = 1), for the metadata checks'
    # messages; None when the table was built in code.
    source_file: str | None = None
    source_line: NDArray[np.int64] | None = None

    def __len__(self) -> int:
        return len(self.beacon_id)

    def active_at(self, time: np.datetime64) -> NDArray[np.bool_]:
        """Which beacons transmit at `time` (an empty start or end is open)."""
        after_start = np.isnat(self.start) | (self.start <= time)
        before_end = np.isnat(self.end) | (time <= self.end)
        return after_start & before_end

    def index_of(self) -> dict[str, int]:
        return {b: i for i, b in enumerate(self.beacon_id)}


@dataclass(frozen=True)
class FloatInfo:
    """One float's launch (and optional end) fix, clock offsets and storage limits."""

    float_id: str
    launch_time: np.datetime64
    launch_lat: float
    launch_lon: float
    end_time: np.datetime64
    end_lat: float
    end_lon: float
    clock_offset_start_s: float
    clock_offset_end_s: float  # NaN: not measured (the clock's drift is then estimated)
    window_s: float
    max_signals: int
    # A smooth correction to the linear clock model (knot times, seconds), interpolated
    # linearly; estimated by calibration from the arrival times themselves.
    clock_residual: tuple[NDArray[np.datetime64], NDArray[np.float64]] | None = None
    # The float's drifting depth (m, positive down; NaN = not given): the sea floor must be
    # deeper (`rafostrack.context`).
    depth_m: float = float("nan")
    # Where the float's row was read (file, line: header = 1), for the metadata checks'
    # messages; None when the float was described in code.
    source: tuple[str, int] | None = None

    def clock_offset_s(self, time: NDArray[np.datetime64] | np.datetime64) -> NDArray[np.float64]:
        """Float clock error (float clock minus true time): linear from launch to end (the
        start offset throughout when the end offset was not measured), plus the calibrated
        residual when there is one."""
        if np.isnat(self.end_time) or self.end_time <= self.launch_time or not self.has_end_clock:
            linear = np.full(np.shape(time), self.clock_offset_start_s)
        else:
            frac = (time - self.launch_time) / (self.end_time - self.launch_time)
            linear = np.asarray(
                self.clock_offset_start_s + frac * (self.clock_offset_end_s - self.clock_offset_start_s)
            )
        if self.clock_residual is None:
            return linear
        knots, seconds = self.clock_residual
        at = np.asarray(time, dtype="datetime64[ns]").astype(np.int64).astype(float)
        return linear + np.interp(at, knots.astype("datetime64[ns]").astype(np.int64).astype(float), seconds)

    @property
    def has_end_clock(self) -> bool:
        """Whether the clock's offset at the end was measured (floats.csv clock_offset_end_s)."""
        return not np.isnan(self.clock_offset_end_s)

    @property
    def has_end_fix(self) -> bool:
        return not (np.isnat(self.end_time) or np.isnan(self.end_lat) or np.isnan(self.end_lon))


@dataclass(frozen=True)
class Window:
    """One listening window: its opening time and the stored arrival times, ascending."""

    time: np.datetime64
    toa_s: NDArray[np.float64]
    beacon_id: tuple[str | None, ...] | None = None  # known labels (None entry = clutter)
    quality: NDArray[np.float64] | None = None  # correlation height per TOA (NaN = none), if the file has it

    @property
    def n_signals(self) -> int:
        return len(self.toa_s)


@dataclass(frozen=True)
class LateArrival:
    """A TOA later than the float's window_s, which the reader left out of its window (the
    index of the window in the record), with its label and correlation height, if any."""

    window: int
    toa_s: float
    beacon_id: str | None = None
    quality: float = float("nan")


@dataclass(frozen=True)
class ArrivalRecord:
    """A float's listening windows in time order."""

    float_id: str
    path: Path
    windows: tuple[Window, ...]
    # The TOAs the reader dropped as later than the float's window_s, by window and TOA:
    # evidence that the float listened longer than its table says (`calibrate.window_check`).
    late: tuple[LateArrival, ...] = ()

    @property
    def has_labels(self) -> bool:
        return bool(self.windows) and self.windows[0].beacon_id is not None


@dataclass(frozen=True)
class PositionFix:
    """A position known at a time (a GPS fix at launch or surfacing), sd per axis in km."""

    time: np.datetime64
    lat: float
    lon: float
    sd_km: float


@dataclass(frozen=True)
class Particles:
    """Particle states: position (degrees) and, for velocity-persistent motion models, the
    east/north velocity (km/day), shape (P, 2); None for position-only models. `clock_s`,
    where the float clock is part of the state (`motion.clock.ClockWalk`), is each
    particle's correction (s) to the table's float clock; None otherwise."""

    lat: NDArray[np.float64]
    lon: NDArray[np.float64]
    velocity_km_per_day: NDArray[np.float64] | None = None
    clock_s: NDArray[np.float64] | None = None

    def __len__(self) -> int:
        return len(self.lat)

    def take(self, index: NDArray[np.intp]) -> Particles:
        """The particles at `index` (e.g. resampled ancestors), copied."""
        vel = None if self.velocity_km_per_day is None else self.velocity_km_per_day[index]
        clock = None if self.clock_s is None else self.clock_s[index]
        return Particles(self.lat[index], self.lon[index], vel, clock)

    def reversed(self) -> Particles:
        """The same positions with velocities negated (for a filter run backwards in time)."""
        vel = None if self.velocity_km_per_day is None else -self.velocity_km_per_day
        return Particles(self.lat, self.lon, vel, self.clock_s)

    def replace_at(self, index: NDArray[np.intp], other: Particles) -> Particles:
        """A copy with the particles at `index` replaced by `other` (same length as `index`):
        the velocity where both have one; the clock where both have one, else `self`'s (a
        data-driven proposal redraws the position and carries the motion's clock over)."""
        lat, lon = self.lat.copy(), self.lon.copy()
        lat[index], lon[index] = other.lat, other.lon
        vel = None
        if other.velocity_km_per_day is not None:
            vel = _replaced(self.velocity_km_per_day, index, other.velocity_km_per_day)
        return Particles(lat, lon, vel, _replaced(self.clock_s, index, other.clock_s))

    def with_clock(self, clock_s: NDArray[np.float64] | None) -> Particles:
        """The same particles with the float clock corrections `clock_s` (None: none)."""
        return Particles(self.lat, self.lon, self.velocity_km_per_day, clock_s)

    @staticmethod
    def concat(parts: list[Particles]) -> Particles:
        vel = None
        if all(p.velocity_km_per_day is not None for p in parts):
            vel = np.concatenate([p.velocity_km_per_day for p in parts])  # type: ignore[misc]
        clock = None
        if all(p.clock_s is not None for p in parts):
            clock = np.concatenate([p.clock_s for p in parts])  # type: ignore[misc]
        return Particles(np.concatenate([p.lat for p in parts]), np.concatenate([p.lon for p in parts]), vel, clock)


def _replaced(values: NDArray | None, index: NDArray[np.intp], other: NDArray | None) -> NDArray | None:
    """`values` with the rows at `index` set to `other`'s, or kept where `other` is None."""
    if values is None or other is None:
        return values
    values = values.copy()
    values[index] = other
    return values


@dataclass(frozen=True)
class Cloud:
    """One step's weighted particles: states at `time` and normalised weights."""

    time: np.datetime64
    particles: Particles
    weights: NDArray[np.float64]

    @property
    def lat(self) -> NDArray[np.float64]:
        return self.particles.lat

    @property
    def lon(self) -> NDArray[np.float64]:
        return self.particles.lon
