"""The particle filter over float position with per-window association (paper Alg. 1).

For each window: propagate particles with the random walk, weight each by the window's
likelihood p(T_1..T_K | X) (the association sum, by the configured engine), record the
posterior summary and the association marginals averaged over particles, then resample
(systematic) when the effective sample size drops below the threshold. Weights stay in
log space throughout.

Methods: `exact` (ranked model, exact subset DP), `bp` (ranked model, loopy BP with the
Bethe estimate), `unranked` (baseline of eq. 19, exact sum), `labeled` (hand labels,
eq. 20).
"""

from __future__ import annotations

import zlib
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from . import model as m
from .config import Config
from .engines import Association
from .engines import exact as exact_engine
from .errors import InputError
from .geodesy import displace, local_offsets_km
from .inputs import ArrivalRecord, BeaconTable, FloatInfo, Window
from .motion import propagate, scatter
from .resampling import ess, normalise_log_weights, systematic

Engine = Callable[[NDArray, NDArray], Association]

TRACK_COLUMNS = ("float_id", "time", "lat", "lon", "sd_km", "ess", "n_signals", "loglik")
LABEL_COLUMNS = ("float_id", "time", "rank", "toa_s", "beacon_id", "prob", "p_clutter")


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


@dataclass(frozen=True)
class PosteriorSummary:
    lat: float
    lon: float
    cov_km2: NDArray[np.float64]  # 2x2 east/north covariance

    @property
    def sd_km(self) -> float:
        """RMS distance of the posterior from its mean: sqrt(trace of the covariance)."""
        return float(np.sqrt(max(np.trace(self.cov_km2), 0.0)))


def summarise(lat: NDArray, lon: NDArray, weights: NDArray) -> PosteriorSummary:
    """Weighted mean and east/north covariance, in the tangent plane of the heaviest particle."""
    ref = int(np.argmax(weights))
    east, north = local_offsets_km(lat, lon, lat[ref], lon[ref])
    mean_e, mean_n = weights @ east, weights @ north
    de, dn = east - mean_e, north - mean_n
    cov = np.array([[weights @ (de * de), weights @ (de * dn)], [weights @ (de * dn), weights @ (dn * dn)]])
    mlat, mlon = displace(np.array([lat[ref]]), np.array([lon[ref]]), np.array([mean_e]), np.array([mean_n]))
    return PosteriorSummary(float(mlat[0]), float(mlon[0]), cov)


@dataclass(frozen=True)
class FilterOutput:
    track: pd.DataFrame
    labels: pd.DataFrame
    n_resamples: int


class ParticleFilter:
    """Bootstrap particle filter for one float (see module docstring)."""

    def __init__(self, beacons: BeaconTable, info: FloatInfo, config: Config):
        self.beacons = beacons
        self.info = info
        self.config = config
        self.method = config.filter.method
        self.engine = engine_for(config)
        self._beacon_row = beacons.index_of()

    def window_loglik(
        self, lat: NDArray, lon: NDArray, window: Window
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], m.WindowBeacons]:
        """Per-particle log p(T | X) and association marginals (P, s, K) for one window."""
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
        assoc = self.engine(factors.log_match, factors.log_unheard)
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
        return m.labeled_loglik(mu, window.toa_s, label_index, self.config.model), p_match, wb

    def run(self, record: ArrivalRecord, rng: np.random.Generator) -> FilterOutput:
        """Filter the whole record; return the per-window track and per-TOA labels."""
        cfg = self.config
        n = cfg.filter.particles
        lat, lon = scatter(
            np.full(n, self.info.launch_lat), np.full(n, self.info.launch_lon), cfg.motion.launch_sd_km, rng
        )
        log_w = np.zeros(n)
        t_prev = self.info.launch_time
        track_rows, label_rows = [], []
        n_resamples = 0
        for window in record.windows:
            dt_days = (window.time - t_prev) / np.timedelta64(1, "s") / m.SECONDS_PER_DAY
            lat, lon = propagate(lat, lon, dt_days, cfg.motion.diffusion_km_per_day, rng)
            t_prev = window.time
            loglik, p_match, wb = self.window_loglik(lat, lon, window)
            if not np.all(np.isfinite(loglik)):
                raise FloatingPointError(
                    f"{self.info.float_id}: non-finite likelihood at window {window.time}; check the model settings"
                )
            _, log_prior = normalise_log_weights(log_w)
            weights, log_post = normalise_log_weights(log_w + loglik)
            log_w = log_w + loglik
            post = summarise(lat, lon, weights)
            eff = ess(weights)
            track_rows.append(
                (
                    record.float_id,
                    window.time,
                    post.lat,
                    post.lon,
                    post.sd_km,
                    eff,
                    window.n_signals,
                    log_post - log_prior,
                )
            )
            label_rows.extend(self._label_rows(record.float_id, window, wb, np.einsum("p,psk->sk", weights, p_match)))
            if eff < cfg.filter.resample_ess_fraction * n:
                idx = systematic(weights, rng)
                lat, lon, log_w = lat[idx], lon[idx], np.zeros(n)
                n_resamples += 1
        track = pd.DataFrame(track_rows, columns=list(TRACK_COLUMNS))
        track["time"] = pd.to_datetime(track["time"])
        labels = pd.DataFrame(label_rows, columns=list(LABEL_COLUMNS))
        labels["time"] = pd.to_datetime(labels["time"])
        return FilterOutput(track=track, labels=labels.astype({"rank": "int64"}), n_resamples=n_resamples)

    def _label_rows(self, float_id: str, window: Window, wb: m.WindowBeacons, probs: NDArray) -> list[tuple]:
        """One row per TOA: the most probable of (each beacon, clutter) and its probability."""
        rows = []
        p_clutter = np.clip(1.0 - probs.sum(axis=0), 0.0, 1.0)
        for j, toa in enumerate(window.toa_s):
            best = int(np.argmax(probs[:, j])) if probs.shape[0] else -1
            if best >= 0 and probs[best, j] > p_clutter[j]:
                beacon, prob = self.beacons.beacon_id[wb.index[best]], float(probs[best, j])
            else:
                beacon, prob = None, float(p_clutter[j])
            rows.append((float_id, window.time, j + 1, float(toa), beacon, prob, float(p_clutter[j])))
        return rows
