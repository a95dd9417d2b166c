"""The particle filter over float position with per-window association (paper Alg. 1).

For each window: propagate particles with the random walk, weight each by the window's
likelihood p(T_1..T_K | X) (the association sum, by the configured engine), keep the
weighted cloud and the association marginals averaged over it, then resample
(systematic) when the effective sample size drops below the threshold. The end fix, when
used, is one more observation: a Gaussian position measurement at `end_time`. Weights stay
in log space throughout. The kept clouds are what the smoother reweights.

Methods: `exact` (ranked model, exact subset DP), `bp` (ranked model, loopy BP with the
Bethe estimate), `unranked` (baseline of eq. 19, exact sum), `labeled` (hand labels,
eq. 20).
"""

from __future__ import annotations

import zlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from functools import partial

import numpy as np
from numpy.typing import NDArray

from . import model as m
from .config import Config
from .engines import Association
from .engines import exact as exact_engine
from .errors import InputError
from .geodesy import local_offsets_km
from .inputs import ArrivalRecord, BeaconTable, FloatInfo, Window
from .motion import propagate, scatter
from .resampling import ess, normalise_log_weights, systematic
from .smoother import Cloud

Engine = Callable[..., Association]  # (log_match, log_unheard, *, marginals=True) -> Association
# Particles carrying less than this fraction of the mass are left out when association
# marginals are recomputed for a reweighted (smoothed) cloud.
_NEGLIGIBLE_MASS = 1e-6
# A Gaussian observation (a hand-labelled TOA, the end fix) farther than OUTLIER_SD sd from
# every particle is one no particle explains: its weights would collapse the cloud onto
# the single nearest particle. Its sd is widened so that the nearest particle sits at
# RECOVER_SD sd, and a warning is recorded.
OUTLIER_SD = 6.0
RECOVER_SD = 3.0


def outlier_scale(z_nearest: NDArray | float) -> NDArray:
    """Factor widening an observation's sd: z / RECOVER_SD where the nearest particle is
    z > OUTLIER_SD sd away, else 1."""
    z = np.asarray(z_nearest, dtype=float)
    return np.where(z > OUTLIER_SD, z / RECOVER_SD, 1.0)


def engine_for(config: Config) -> Engine | None:
    """The association engine of the configured method (None for `labeled`)."""
    method = config.filter.method
    if method in ("exact", "unranked"):
        return exact_engine.associate
    if method == "bp":
        from .engines import bp

        return partial(bp.associate, tolerance=config.bp.tolerance, max_iterations=config.bp.max_iterations)
    return None


def float_rng(seed: int, float_id: str) -> np.random.Generator:
    """The float's generator: seeded from the config seed and the float id, so a float's
    result does not depend on which other floats are processed, or in which order."""
    return np.random.default_rng([seed, zlib.crc32(float_id.encode("utf-8"))])


def fix_loglik(lat: NDArray, lon: NDArray, fix_lat: float, fix_lon: float, sd_km: float) -> NDArray:
    """log N(X - fix; 0, sd^2 I) of a position fix, in the fix's tangent plane."""
    east, north = local_offsets_km(lat, lon, fix_lat, fix_lon)
    return -(east * east + north * north) / (2.0 * sd_km * sd_km) - np.log(2.0 * np.pi * sd_km * sd_km)


def fix_distances_km(lat: NDArray, lon: NDArray, fix_lat: float, fix_lon: float) -> NDArray:
    east, north = local_offsets_km(lat, lon, fix_lat, fix_lon)
    return np.hypot(east, north)


@dataclass(frozen=True)
class Step:
    """One filter step: a listening window, or the end fix (`window` is None)."""

    cloud: Cloud
    loglik: float  # log p(y_t | y_1..t-1), the step's evidence
    ess: float
    window: Window | None
    beacon_index: NDArray[np.intp]  # beacon-table rows of the label_probs rows
    label_probs: NDArray[np.float64] | None  # (s, K) filtered P(signal j from beacon i), if kept


@dataclass(frozen=True)
class FilterRun:
    float_id: str
    steps: list[Step]
    n_resamples: int
    warnings: list[str]

    @property
    def window_steps(self) -> list[Step]:
        return [s for s in self.steps if s.window is not None]


class ParticleFilter:
    """Bootstrap particle filter for one float (see module docstring)."""

    def __init__(self, beacons: BeaconTable, info: FloatInfo, config: Config, *, label_probs: bool = True):
        """`label_probs=False` skips the filtered association marginals (when only smoothed
        labels are wanted, which are recomputed after smoothing)."""
        self.label_probs = label_probs
        self.beacons = beacons
        self.info = info
        self.config = config
        self.method = config.filter.method
        self.engine = engine_for(config)
        self._beacon_row = beacons.index_of()
        self.warnings: list[str] = []
        self.n_resamples = 0

    def _warn(self, message: str) -> None:
        self.warnings.append(message)

    def window_loglik(
        self, lat: NDArray, lon: NDArray, window: Window, *, marginals: bool = True
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], m.WindowBeacons]:
        """Per-particle log p(T | X) and association marginals (P, s, K) for one window
        (marginals may be NaN when `marginals` is False: see `rafostrack.engines`)."""
        if self.method == "labeled":
            return self._labeled_loglik(lat, lon, window)
        model = self.config.model
        wb = m.window_beacons(self.beacons, self.info, window.time)
        ranges = m.beacon_ranges_m(lat, lon, wb)
        factors = m.association_factors(
            m.predicted_toa_s(ranges, wb, model),
            m.detection_prob(ranges, model),
            window.toa_s,
            max_signals=self.info.max_signals,
            window_s=self.info.window_s,
            model=model,
            ranked=self.method != "unranked",
        )
        assoc = self.engine(factors.log_match, factors.log_unheard, marginals=marginals)
        return factors.log_base + assoc.log_z, assoc.p_match, wb

    def _labeled_loglik(
        self, lat: NDArray, lon: NDArray, window: Window
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], m.WindowBeacons]:
        """Eq. (20) on the window's labelled beacons (active period not enforced: the label says
        the beacon was heard)."""
        if window.beacon_id is None:
            raise InputError(f"method 'labeled' needs a beacon_id column in the arrival file of {self.info.float_id}")
        rows = np.array(sorted({self._beacon_row[b] for b in window.beacon_id if b is not None}), dtype=np.intp)
        wb = m.window_beacons(self.beacons, self.info, window.time, index=rows)
        mu = m.predicted_toa_s(m.beacon_ranges_m(lat, lon, wb), wb, self.config.model)
        column = {int(r): c for c, r in enumerate(rows)}
        label_index = np.array(
            [column[self._beacon_row[b]] if b is not None else -1 for b in window.beacon_id], dtype=np.intp
        )
        p_match = np.zeros((len(lat), len(rows), window.n_signals))
        labelled = np.flatnonzero(label_index >= 0)
        p_match[:, label_index[labelled], labelled] = 1.0
        nearest = np.full(window.n_signals, 0.0)
        if len(labelled):
            resid = window.toa_s[labelled][None, :] - mu[:, label_index[labelled]]
            nearest[labelled] = np.abs(resid).min(axis=0) / self.config.model.toa_sigma_s
        scale = outlier_scale(nearest)
        for j in np.flatnonzero(scale > 1.0):
            self._warn(
                f"{self.info.float_id}: window {np.datetime_as_string(window.time, 's')}Z: TOA {window.toa_s[j]:g} s "
                f"labelled {window.beacon_id[j]} is {nearest[j]:.0f} sd from every particle's prediction; "
                f"its sd was widened {scale[j]:.1f}x"
            )
        loglik = m.labeled_loglik(mu, window.toa_s, label_index, self.config.model, sigma_scale=scale)
        return loglik, p_match, wb

    def association_probs(self, cloud: Cloud, weights: NDArray, window: Window) -> tuple[NDArray, NDArray]:
        """Association marginals (s, K) of a window under `weights` on the cloud's particles.

        Used for smoothed labels: recomputes the per-particle marginals on the particles
        that carry all but a negligible fraction of the mass.
        """
        order = np.argsort(weights)[::-1]
        cut = np.searchsorted(np.cumsum(weights[order]), 1.0 - _NEGLIGIBLE_MASS) + 1
        keep = np.sort(order[:cut])
        _, p_match, wb = self.window_loglik(cloud.lat[keep], cloud.lon[keep], window)
        w = weights[keep] / weights[keep].sum()
        return np.einsum("p,psk->sk", w, p_match), wb.index

    def _end_fix_time(self) -> np.datetime64 | None:
        use = self.config.fixes.use_end_fix and self.info.has_end_fix
        return self.info.end_time if use else None

    def run(self, record: ArrivalRecord, rng: np.random.Generator) -> FilterRun:
        """Filter the whole record (and the end fix); keep every step's weighted cloud."""
        steps = list(self.steps(record, rng))
        return FilterRun(record.float_id, steps, self.n_resamples, list(self.warnings))

    def steps(self, record: ArrivalRecord, rng: np.random.Generator) -> Iterator[Step]:
        """Filter the record step by step, yielding each weighted cloud as it is made, so a
        caller that needs no history (no smoothing) holds one step at a time.
        `self.n_resamples` and `self.warnings` are complete once the iteration ends."""
        cfg = self.config
        n = cfg.filter.particles
        lat, lon = scatter(
            np.full(n, self.info.launch_lat), np.full(n, self.info.launch_lon), cfg.fixes.launch_sd_km, rng
        )
        log_w = np.zeros(n)
        t_prev = self.info.launch_time
        self.n_resamples = 0
        self.warnings = []
        fix_time = self._end_fix_time()
        events: list[Window | None] = list(record.windows)
        if fix_time is not None:  # the fix goes after every window at or before its time
            events.insert(int(np.searchsorted([w.time for w in record.windows], fix_time, side="right")), None)
        for window in events:
            time = fix_time if window is None else window.time
            dt_days = (time - t_prev) / np.timedelta64(1, "s") / m.SECONDS_PER_DAY
            lat, lon = propagate(lat, lon, dt_days, cfg.motion.diffusion_km_per_day, rng)
            t_prev = time
            if window is None:
                loglik = self._end_fix_loglik(lat, lon)
                p_match, index = np.zeros((n, 0, 0)), np.zeros(0, dtype=np.intp)
            else:
                loglik, p_match, wb = self.window_loglik(lat, lon, window, marginals=self.label_probs)
                index = wb.index
            loglik, skipped = self._finite_loglik(loglik, time)
            _, log_prior = normalise_log_weights(log_w)
            log_w = log_w + loglik
            weights, log_post = normalise_log_weights(log_w)
            eff = ess(weights)
            yield Step(
                cloud=Cloud(time, lat, lon, weights),
                loglik=np.nan if skipped else log_post - log_prior,
                ess=eff,
                window=window,
                beacon_index=index,
                label_probs=np.einsum("p,psk->sk", weights, p_match) if self.label_probs else None,
            )
            if eff < cfg.filter.resample_ess_fraction * n:
                idx = systematic(weights, rng)
                lat, lon, log_w = lat[idx], lon[idx], np.zeros(n)
                self.n_resamples += 1

    def _finite_loglik(self, loglik: NDArray, time: np.datetime64) -> tuple[NDArray, bool]:
        """Guard against a non-finite likelihood (a bug or an extreme setting, not data: the
        model always keeps an all-clutter explanation). Particles with one get zero weight;
        if none is finite the step is skipped (no update), with a warning either way.
        Returns the log-likelihood to use and whether the step was skipped."""
        bad = ~np.isfinite(loglik)
        if not bad.any():
            return loglik, False
        when = f"{self.info.float_id}: {np.datetime_as_string(time, 's')}Z"
        if bad.all():
            self._warn(f"{when}: likelihood not finite for any particle; this step was skipped")
            return np.zeros_like(loglik), True
        self._warn(f"{when}: likelihood not finite for {int(bad.sum())} particle(s); they were dropped")
        return np.where(bad, -np.inf, loglik), False

    def _end_fix_loglik(self, lat: NDArray, lon: NDArray) -> NDArray:
        """The end fix's likelihood, its sd widened if no particle is near it."""
        sd = self.config.fixes.end_sd_km
        nearest = float(fix_distances_km(lat, lon, self.info.end_lat, self.info.end_lon).min())
        scale = float(outlier_scale(nearest / sd))
        if scale > 1.0:
            self._warn(
                f"{self.info.float_id}: the end fix is {nearest:.1f} km from every particle "
                f"({nearest / sd:.0f} sd); its sd was widened to {sd * scale:.1f} km"
            )
        return fix_loglik(lat, lon, self.info.end_lat, self.info.end_lon, sd * scale)
