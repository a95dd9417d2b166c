"""Peers, side by side: one labelled-arrival particle filter in rafostrack, Stone Soup and `particles`.

The problem: the bundled sample float767 (`rafostrack/data/samples`, simulated arrival times
whose `beacon_id` column holds the true source of each TOA), its first K listening windows,
filtered from the launch fix with N particles. The state is the float's position, its motion a
random walk of `diffusion_km_per_day` per axis (rafostrack's `motion.model = "random_walk"`,
no mean current), the launch fix N(0, launch_sd_km^2) per axis, and a window's evidence the
product over its labelled TOAs of N(T_j; mu_{R_j}(X), toa_sigma_s^2), mu the source's delay
(offset, clock drift and the float's clock offset) plus range / sound speed (rafostrack's
`likelihood = "labeled"`, eq. 20; TOAs labelled clutter are ignored). All three resample
systematically when the effective sample size falls below N/2, and report the weighted mean
position at each window. Each implementation is timed over the whole run (best of
`--repeats`), after an untimed warm-up on a few windows (imports, numba caches):

1. rafostrack, labelled: `Tracker.from_problem(...).run_filter(record)` with calibration,
   smoother, recovery and the end fix off (the filter alone, association marginals off), and
   the same run through `Tracker.track` (the filter plus the per-window summary: modes,
   ellipses, labels), the call a user makes;
2. Stone Soup: `ParticlePredictor` with a `CombinedLinearGaussianTransitionModel` of two
   `RandomWalk`s (km, seconds), `ParticleUpdater` with an `ESSResampler` around a
   `SystematicResampler`, and a custom `MeasurementModel` (one per window, carried by its
   `Detection`) whose `function` gives the predicted TOAs of the window's labelled sources;
3. `particles`: a `StateSpaceModel` whose PY is a distribution over the window's labelled
   TOAs, run by `SMC` on its `Bootstrap` Feynman-Kac model, moments collected.

Beside them, the exact engine (`likelihood = "ranked"`, `engine = "exact"`: the labels unused,
the association summed out) on the same particles, windows and motion, for what the unlabelled
problem costs per window.

Printed per implementation: N, windows, seconds, particle-windows per second, the ratio of
rafostrack's labelled filter throughput to the row's (above 1: rafostrack is faster), the
cost per window, and the RMSE (km) of the filtered mean against the sample's true track, to
show that the runs do the same job (a peer that lost the float would be no comparison).

    OMP_NUM_THREADS=1 python benchmarks/peers.py [--particles 10000] [--windows 729] [--repeats 1]

Caveats:
- Geometry: the peers work in a plane about the launch point: the azimuthal equidistant
  projection on the sphere of the Gaussian radius of curvature there, where ranges from the
  launch point are exact and others distorted by under 1% over this mission (predicted TOAs at
  the true track: residual sd 2.06 s against 1.97 s with rafostrack's ellipsoidal ranges; the
  equirectangular plane of `geodesy.local_offsets_km` is off by 16 s sd over the mission, up to
  113 s, and would lose the float). rafostrack uses ellipsoidal ranges and moves each particle
  in its own tangent plane. The models are the same in N, windows, motion noise and observation noise, not bit for
  bit, and each draws its own random numbers: the RMSEs agree to Monte Carlo error, not exactly.
- rafostrack's filter does a little more per window than the peers: it resamples each mode of
  the cloud on its own (`[filter] mode_link_km`), and widens the sd of a labelled TOA that no
  particle explains (an outlier guard; with the sample's Gaussian TOAs it rarely fires).
- `particles` 0.4 (its latest release) declares numpy<2, so `pip install -e '.[bench]'` brings
  numpy down to 1.26; it runs as well on numpy 2 (`pip install joblib scikit-learn`, then
  `pip install --no-deps particles`). Its own `__version__` says 0.3alpha.
- Stone Soup and `particles` draw from numpy's global generator (seeded with `--seed`).
- One process, one core: run with OMP_NUM_THREADS=1 and nothing else heavy on the machine.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import particles
from numpy.typing import NDArray
from particles import collectors
from particles import distributions as dists
from particles import state_space_models as ssm
from stonesoup.base import Property
from stonesoup.models.measurement.base import MeasurementModel
from stonesoup.models.transition.linear import CombinedLinearGaussianTransitionModel, RandomWalk
from stonesoup.predictor.particle import ParticlePredictor
from stonesoup.resampler.particle import ESSResampler, SystematicResampler
from stonesoup.types.array import StateVector, StateVectors
from stonesoup.types.detection import Detection
from stonesoup.types.hypothesis import SingleHypothesis
from stonesoup.types.state import ParticleState
from stonesoup.updater.particle import ParticleUpdater

from rafostrack.config import Config, with_overrides
from rafostrack.domain import ArrivalRecord, BeaconTable, FloatInfo
from rafostrack.filtering.filter import Step
from rafostrack.model import measurement as m
from rafostrack.model.geodesy import radii_of_curvature_m
from rafostrack.problem import FloatProblem
from rafostrack.run.one_float import TrackInputs, load_float
from rafostrack.run.one_pass import Tracker
from rafostrack.sim.evaluate import rmse_km
from rafostrack.sim.scenarios import sample_mission_dir

SAMPLE = sample_mission_dir() / "float767.csv"
HALF_LOG_2PI = 0.5 * np.log(2.0 * np.pi)
WARMUP_WINDOWS = 5
WARMUP_PARTICLES = 200


@dataclass(frozen=True)
class Plane:
    """Azimuthal equidistant projection (km) about (lat0, lon0) on a sphere of radius R (km)."""

    lat0: float
    lon0: float
    radius_km: float

    @classmethod
    def about(cls, lat0: float, lon0: float) -> Plane:
        """The plane about a point, on the sphere of its Gaussian radius of curvature sqrt(M N)."""
        meridional, normal = radii_of_curvature_m(lat0)
        return cls(lat0, lon0, float(np.sqrt(meridional * normal)) / 1e3)

    def forward(self, lat: NDArray, lon: NDArray) -> tuple[NDArray, NDArray]:
        p0, p, dl = np.radians(self.lat0), np.radians(lat), np.radians(np.asarray(lon) - self.lon0)
        cos_c = np.clip(np.sin(p0) * np.sin(p) + np.cos(p0) * np.cos(p) * np.cos(dl), -1.0, 1.0)
        c = np.arccos(cos_c)
        k = np.where(c > 0, c / np.sin(np.where(c > 0, c, 1.0)), 1.0)
        x = k * np.cos(p) * np.sin(dl)
        y = k * (np.cos(p0) * np.sin(p) - np.sin(p0) * np.cos(p) * np.cos(dl))
        return self.radius_km * x, self.radius_km * y

    def inverse(self, x: NDArray, y: NDArray) -> tuple[NDArray, NDArray]:
        x, y = np.asarray(x) / self.radius_km, np.asarray(y) / self.radius_km
        p0 = np.radians(self.lat0)
        c = np.hypot(x, y)
        safe = np.where(c > 0, c, 1.0)
        lat = np.arcsin(np.cos(c) * np.sin(p0) + np.where(c > 0, y * np.sin(c) * np.cos(p0) / safe, 0.0))
        lon = np.arctan2(x * np.sin(c), c * np.cos(p0) * np.cos(c) - y * np.sin(p0) * np.sin(c))
        return np.degrees(lat), self.lon0 + np.degrees(lon)


@dataclass(frozen=True)
class PeerWindow:
    """One window as the peers see it: its labelled TOAs and their sources in the plane."""

    time: np.datetime64
    dt_days: float  # since the previous window (the first: since launch)
    toa_s: NDArray[np.float64]  # (m,) labelled TOAs
    beacon_xy_km: NDArray[np.float64]  # (m, 2) their sources
    delay_s: NDArray[np.float64]  # (m,) their sources' delays

    @property
    def when(self) -> datetime.datetime:
        return pd.Timestamp(self.time).to_pydatetime()


@dataclass(frozen=True)
class Problem:
    """The shared problem: rafostrack's inputs and configuration, and the peers' view of them."""

    beacons: BeaconTable
    info: FloatInfo
    config: Config  # labelled, random walk; calibration, smoother, recovery, end fix off
    record: ArrivalRecord  # the first K windows
    plane: Plane
    windows: tuple[PeerWindow, ...]
    truth: pd.DataFrame

    @property
    def n_particles(self) -> int:
        return self.config.filter.particles

    @property
    def launch_sd_km(self) -> float:
        return self.config.fixes.launch_sd_km

    @property
    def diffusion_km_per_day(self) -> float:
        return self.config.motion.diffusion_km_per_day

    @property
    def toa_sigma_s(self) -> float:
        return self.config.model.toa_sigma_s

    @property
    def sound_speed_km_s(self) -> float:
        return self.config.model.sound_speed_m_s / 1e3

    def launch_datetime(self) -> datetime.datetime:
        return pd.Timestamp(self.info.launch_time).to_pydatetime()

    def resized(self, n_particles: int, n_windows: int) -> Problem:
        """The same problem with fewer particles and windows (the warm-up)."""
        return dataclasses.replace(
            self,
            config=with_overrides(self.config, filter={"particles": n_particles}),
            record=dataclasses.replace(self.record, windows=self.record.windows[:n_windows]),
            windows=self.windows[:n_windows],
        )


def load_problem(float_file: Path, n_particles: int, n_windows: int | None) -> Problem:
    """The sample float's first `n_windows` windows (all when None) with `n_particles`."""
    loaded = load_float(TrackInputs(float_file))
    config = with_overrides(
        loaded.problem.config,
        calibrate={"enabled": False},
        smoother={"enabled": False},
        recovery={"enabled": False},
        fixes={"use_end_fix": False},
        motion={"model": "random_walk", "mean_current_east_km_per_day": 0.0, "mean_current_north_km_per_day": 0.0},
        model={"multipath_fraction": 0.0},
        # The peers' rule (rafostrack's default resamples at every window).
        filter={"likelihood": "labeled", "particles": n_particles, "resample_ess_fraction": 0.5},
    )
    record = loaded.record
    record = dataclasses.replace(record, windows=record.windows[: n_windows or len(record.windows)])
    info, beacons = loaded.problem.info, loaded.problem.beacons
    plane = Plane.about(info.launch_lat, info.launch_lon)
    bx, by = plane.forward(beacons.lat, beacons.lon)
    row = beacons.index_of()
    windows, t_prev = [], info.launch_time
    for w in record.windows:
        if w.beacon_id is None:
            raise ValueError(f"{float_file}: no beacon_id column; the peers need labelled arrivals")
        labelled = [j for j, b in enumerate(w.beacon_id) if b is not None]
        rows = np.array([row[w.beacon_id[j]] for j in labelled], dtype=np.intp)  # type: ignore[index]
        delay = m.window_beacons(beacons, info, w.time, index=rows).delay_s
        dt_days = float((w.time - t_prev) / np.timedelta64(1, "s")) / 86400.0
        windows.append(PeerWindow(w.time, dt_days, w.toa_s[labelled], np.column_stack([bx[rows], by[rows]]), delay))
        t_prev = w.time
    truth = pd.read_csv(float_file.parent / "truth" / float_file.name, parse_dates=["time"])
    truth["time"] = truth["time"].dt.tz_localize(None)
    return Problem(beacons, info, config, record, plane, tuple(windows), truth)


def predicted_toa_s(problem: Problem, window: PeerWindow, x_km: NDArray, y_km: NDArray) -> NDArray[np.float64]:
    """Predicted TOAs (m, P) of the window's labelled sources from plane positions (P,)."""
    ranges = np.hypot(x_km[None, :] - window.beacon_xy_km[:, :1], y_km[None, :] - window.beacon_xy_km[:, 1:])
    return window.delay_s[:, None] + ranges / problem.sound_speed_km_s


def gaussian_toa_loglik(resid_s: NDArray, sigma_s: float) -> NDArray[np.float64]:
    """Sum over TOAs (axis 0) of log N(resid; 0, sigma^2): one value per particle."""
    z = resid_s / sigma_s
    return -0.5 * np.einsum("mp,mp->p", z, z) - resid_s.shape[0] * (np.log(sigma_s) + HALF_LOG_2PI)


def plane_track(problem: Problem, times: Sequence[np.datetime64], xy_km: NDArray) -> pd.DataFrame:
    lat, lon = problem.plane.inverse(xy_km[:, 0], xy_km[:, 1])
    return pd.DataFrame({"time": pd.to_datetime(np.asarray(times)), "lat": lat, "lon": lon})


# rafostrack ------------------------------------------------------------------------------------


def run_rafostrack(problem: Problem, likelihood: str = "labeled", *, whole_tracker: bool = False) -> pd.DataFrame:
    """rafostrack's filter with `likelihood` (labeled, or ranked with the exact engine); the
    weighted mean position per window. `whole_tracker`: `Tracker.track` (filter and summaries)."""
    config = with_overrides(problem.config, filter={"likelihood": likelihood, "engine": "exact"})
    tracker = Tracker.from_problem(FloatProblem(problem.beacons, problem.info, config))
    if whole_tracker:
        track = tracker.track(problem.record).track
        return pd.DataFrame({"time": track["time"], "lat": track["lat"], "lon": track["lon"]})
    rows: list[tuple[np.datetime64, float, float]] = []

    def mean(step: Step) -> None:
        cloud = step.cloud
        rows.append((cloud.time, float(cloud.weights @ cloud.lat), float(cloud.weights @ cloud.lon)))

    tracker.run_filter(problem.record, label_probs=False, keep=False, on_step=mean)
    return pd.DataFrame(rows, columns=["time", "lat", "lon"])


# Stone Soup ------------------------------------------------------------------------------------


class LabelledToaModel(MeasurementModel):
    """The labelled TOAs of one window: predicted TOA = delay + planar range / c, Gaussian error."""

    beacon_xy_km: np.ndarray = Property(doc="(m, 2) sources of the labelled TOAs, in the plane (km)")
    delay_s: np.ndarray = Property(doc="(m,) delay of each source (offset, drift, float clock)")
    sound_speed_km_s: float = Property(doc="sound speed (km/s)")
    sigma_s: float = Property(doc="TOA error sd (s)")

    @property
    def ndim_meas(self) -> int:
        return len(self.delay_s)

    def function(self, state: Any, noise: bool | np.ndarray = False, **kwargs: Any) -> StateVectors:
        xy = np.asarray(state.state_vector, dtype=float)
        ranges = np.hypot(xy[0][None, :] - self.beacon_xy_km[:, :1], xy[1][None, :] - self.beacon_xy_km[:, 1:])
        toa = self.delay_s[:, None] + ranges / self.sound_speed_km_s
        if isinstance(noise, bool) and noise:
            toa = toa + np.asarray(self.rvs(num_samples=toa.shape[1]))
        elif not isinstance(noise, bool):
            toa = toa + np.asarray(noise)
        return StateVectors(toa)

    def rvs(self, num_samples: int = 1, **kwargs: Any) -> StateVectors:
        return StateVectors(np.random.normal(0.0, self.sigma_s, (self.ndim_meas, num_samples)))  # noqa: NPY002

    def logpdf(self, state1: Any, state2: Any, **kwargs: Any) -> np.ndarray:
        """log p(TOAs of `state1` | each particle of `state2`)."""
        resid = np.asarray(state1.state_vector, dtype=float) - np.asarray(self.function(state2), dtype=float)
        return gaussian_toa_loglik(resid, self.sigma_s)

    def pdf(self, state1: Any, state2: Any, **kwargs: Any) -> np.ndarray:
        return np.exp(self.logpdf(state1, state2, **kwargs))


def run_stonesoup(problem: Problem, seed: int) -> pd.DataFrame:
    """Stone Soup's particle filter on the problem; the weighted mean position per window."""
    np.random.seed(seed)  # noqa: NPY002 (Stone Soup draws from the global generator)
    n = problem.n_particles
    q = problem.diffusion_km_per_day**2 / 86400.0  # km^2 per second: Stone Soup's time is in seconds
    predictor = ParticlePredictor(CombinedLinearGaussianTransitionModel([RandomWalk(q), RandomWalk(q)]))
    updater = ParticleUpdater(
        measurement_model=None, resampler=ESSResampler(threshold=n / 2, resampler=SystematicResampler())
    )
    start = np.random.normal(0.0, problem.launch_sd_km, (2, n))  # noqa: NPY002
    state = ParticleState(StateVectors(start), log_weight=np.full(n, -np.log(n)), timestamp=problem.launch_datetime())
    means = np.empty((len(problem.windows), 2))
    for k, window in enumerate(problem.windows):
        state = predictor.predict(state, timestamp=window.when)
        if len(window.toa_s):
            toa_model = LabelledToaModel(
                ndim_state=2,
                mapping=(0, 1),
                beacon_xy_km=window.beacon_xy_km,
                delay_s=window.delay_s,
                sound_speed_km_s=problem.sound_speed_km_s,
                sigma_s=problem.toa_sigma_s,
            )
            detection = Detection(StateVector(window.toa_s), timestamp=window.when, measurement_model=toa_model)
            state = updater.update(SingleHypothesis(state, detection))
        means[k] = np.asarray(state.mean, dtype=float).ravel()
    return plane_track(problem, [w.time for w in problem.windows], means)


# particles -------------------------------------------------------------------------------------


class LabelledToas(dists.ProbDist):
    """The law of a window's labelled TOAs given plane positions x (P, 2)."""

    def __init__(self, problem: Problem, window: PeerWindow, x: NDArray) -> None:
        self.problem, self.window, self.x = problem, window, x
        self.dim = len(window.toa_s)

    def logpdf(self, y: NDArray) -> NDArray[np.float64]:
        mu = predicted_toa_s(self.problem, self.window, self.x[:, 0], self.x[:, 1])
        return gaussian_toa_loglik(np.asarray(y)[:, None] - mu, self.problem.toa_sigma_s)

    def rvs(self, size: int | None = None) -> NDArray[np.float64]:
        mu = predicted_toa_s(self.problem, self.window, self.x[:, 0], self.x[:, 1]).T
        return mu + np.random.normal(0.0, self.problem.toa_sigma_s, mu.shape)  # noqa: NPY002


class FloatModel(ssm.StateSpaceModel):
    """Position in the plane (km): launch fix, random walk, labelled TOAs."""

    def __init__(self, problem: Problem) -> None:
        super().__init__()
        self.problem = problem
        self.step_sd_km = problem.diffusion_km_per_day * np.sqrt([w.dt_days for w in problem.windows])

    def PX0(self) -> dists.ProbDist:
        # X_0 is the first window's position: the launch fix moved over the time to it.
        sd = np.hypot(self.problem.launch_sd_km, self.step_sd_km[0])
        return dists.MvNormal(loc=np.zeros(2), scale=sd)

    def PX(self, t: int, xp: NDArray) -> dists.ProbDist:
        return dists.MvNormal(loc=xp, scale=self.step_sd_km[t])

    def PY(self, t: int, xp: NDArray | None, x: NDArray) -> dists.ProbDist:
        return LabelledToas(self.problem, self.problem.windows[t], x)


def run_particles(problem: Problem, seed: int) -> pd.DataFrame:
    """The `particles` library's bootstrap filter on the problem; the weighted mean per window."""
    np.random.seed(seed)  # noqa: NPY002 (`particles` draws from the global generator)
    fk = ssm.Bootstrap(ssm=FloatModel(problem), data=[w.toa_s for w in problem.windows])
    alg = particles.SMC(
        fk=fk, N=problem.n_particles, resampling="systematic", ESSrmin=0.5, collect=[collectors.Moments()]
    )
    alg.run()
    means = np.array([moments["mean"] for moments in alg.summaries.moments])
    return plane_track(problem, [w.time for w in problem.windows], means)


# the comparison --------------------------------------------------------------------------------


@dataclass(frozen=True)
class Implementation:
    name: str
    run: Callable[[Problem], pd.DataFrame]


def implementations(seed: int) -> list[Implementation]:
    return [
        Implementation("rafostrack labeled (filter)", run_rafostrack),
        Implementation("rafostrack labeled (Tracker.track)", lambda p: run_rafostrack(p, whole_tracker=True)),
        Implementation("stonesoup", lambda p: run_stonesoup(p, seed)),
        Implementation("particles", lambda p: run_particles(p, seed)),
        Implementation("rafostrack exact, unlabelled (filter)", lambda p: run_rafostrack(p, "ranked")),
    ]


def timed(run: Callable[[Problem], pd.DataFrame], problem: Problem, repeats: int) -> tuple[float, pd.DataFrame]:
    """Best wall time of `repeats` runs, and the last run's track."""
    best, track = np.inf, pd.DataFrame()
    for _ in range(repeats):
        started = time.perf_counter()
        track = run(problem)
        best = min(best, time.perf_counter() - started)
    return best, track


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--float-file", type=Path, default=SAMPLE)
    parser.add_argument("--particles", type=int, default=10000)
    parser.add_argument("--windows", type=int, default=None, help="the first K windows (default: all)")
    parser.add_argument("--repeats", type=int, default=1, help="timed runs per implementation (best is kept)")
    parser.add_argument("--seed", type=int, default=0, help="the peers' global numpy seed")
    args = parser.parse_args()

    problem = load_problem(args.float_file, args.particles, args.windows)
    n_windows, n_toas = len(problem.windows), sum(len(w.toa_s) for w in problem.windows)
    print(
        f"{args.float_file.name}: {n_windows} windows ({n_toas} labelled TOAs), {args.particles} particles, "
        f"random walk {problem.diffusion_km_per_day:g} km/day^0.5, TOA sd {problem.toa_sigma_s:g} s, "
        f"best of {args.repeats}"
    )
    warmup = problem.resized(min(args.particles, WARMUP_PARTICLES), min(n_windows, WARMUP_WINDOWS))
    impls = implementations(args.seed)
    for impl in impls:
        impl.run(warmup)
    header = (
        f"{'implementation':<38} {'N':>6} {'windows':>7} {'seconds':>8} {'particle-windows/s':>18} "
        f"{'rafostrack/peer':>15} {'ms/window':>9} {'rmse_km':>7}"
    )
    print(header)
    print("-" * len(header))
    reference = None
    for impl in impls:
        seconds, track = timed(impl.run, problem, args.repeats)
        rate = args.particles * n_windows / seconds
        reference = reference or rate
        print(
            f"{impl.name:<38} {args.particles:>6} {n_windows:>7} {seconds:>8.2f} {rate:>18,.0f} "
            f"{reference / rate:>15.2f} {1e3 * seconds / n_windows:>9.2f} {rmse_km(track, problem.truth):>7.2f}",
            flush=True,
        )


if __name__ == "__main__":
    main()
