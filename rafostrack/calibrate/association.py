"""Multipath, echoes and clutter of a record, by EM at the calibrated track.

The timing fit (`kalman`) uses only confidently labelled arrivals, which a first pass with a
model that under-rates multipath rarely gives to delayed arrivals: their share would be
under-estimated, and the next pass would call them clutter again. Here every stored TOA
counts. At the calibrated track x (every window's position, interpolated between the
smoother's nodes), with the calibrated timing:

E-step: per window, the exact association marginals at x (`engines.exact`: P(signal j is
    beacon i's first arrival), P(... its echo), P(clutter); one engine call for all the
    windows with the same numbers of beacons and signals), the first arrival split into
    direct and delayed by the error density's components, P(delayed | r) = eps f_d(r) / f(r)
    (`model.measurement.toa_logpdf`), r = T_j - mu_i; and the delay's posterior mean given it was
    delayed. A Gamma(k, theta) delay d plus a Gaussian error: d | r has density
    proportional to d^(k-1) phi((d - m) / sigma) on d > 0, m = r - sigma^2 / theta; with
    u = m / sigma and G = phi(u) / Phi(u) (truncated-Gaussian moments),
        k = 1: E[d | r] = sigma (u + G),
        k = 2: E[d | r] = sigma (u^2 + 1 + u G) / (u + G).
M-step: eps = E[#delayed] / E[#first arrivals]; tau = E[sum of delays] / E[#delayed] (the
    maximum-likelihood mean of a Gamma delay of known shape), the delays of multipath and of
    echoes alike (the model gives both the same law; an echo's delay is from its beacon's
    first arrival, at that arrival's expected time);
    e = E[#echoes] / E[#first arrivals whose echo could have been stored], an echo of a
    first arrival at T_j being stored only before the horizon h: weight G(h - T_j);
    clutter rate from the clutter probabilities (`noise.fit_clutter_rate`).

The track is uncertain by a few km: the E-step widens sigma by the arrival-time sd that the
track's position error makes (km / 1.48 km/s), so that an arrival a few sd off the track's
prediction is not taken for multipath.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.special import log_ndtr

from ..config import ModelConfig
from ..domain import ArrivalRecord, BeaconTable, FloatInfo
from ..engines import exact
from ..model import measurement as m
from .noise import direct_probability, fit_clutter_rate

KM_PER_S = 1.48  # range per second of arrival time
ITERATIONS = 8
MIN_FRACTION = 1e-3  # multipath and echo fractions are kept above this (never exactly off)


def _delay_mean(resid_s: NDArray, sigma: float, tau: float, shape: int) -> NDArray:
    """E[d | r] for r = g + d, g ~ N(0, sigma^2), d ~ Gamma(shape k, mean tau) (module
    docstring); 0 where the ratio's floating point gives no number (r many sigma below the
    prediction, where the posterior of being delayed is nil)."""
    mean = resid_s - sigma * sigma * shape / tau
    z = mean / sigma
    hazard = np.exp(-0.5 * z * z - 0.5 * np.log(2 * np.pi) - log_ndtr(z))  # phi(z) / Phi(z)
    if shape == 1:
        return mean + sigma * hazard
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.nan_to_num(sigma * (z * z + 1.0 + z * hazard) / (z + hazard), nan=0.0, posinf=0.0, neginf=0.0)


@dataclass(frozen=True)
class _Batch:
    """The windows with the same numbers of active beacons (s) and stored signals (K), one
    row each: the E-step's association runs on them at once (`model.measurement.association_factors`
    takes a batch of windows)."""

    mu_s: NDArray[np.float64]  # (n, s) predicted arrival times at the track
    p_detect: NDArray[np.float64]  # (n, s)
    toa_s: NDArray[np.float64]  # (n, K)


def _batches(
    record: ArrivalRecord, lat: NDArray, lon: NDArray, beacons: BeaconTable, info: FloatInfo, model: ModelConfig
) -> list[_Batch]:
    """The record's windows with signals, predicted at the track and grouped by shape."""
    rows: dict[tuple[int, int], list[tuple[NDArray, NDArray, NDArray]]] = {}
    for w, la, lo in zip(record.windows, lat, lon, strict=True):
        if w.n_signals:
            _, mu, p_detect = m.window_prediction(beacons, info, model, np.array([la]), np.array([lo]), w.time)
            rows.setdefault((mu.shape[1], w.n_signals), []).append((mu[0], p_detect[0], w.toa_s))
    return [_Batch(*(np.array(column) for column in zip(*group, strict=True))) for group in rows.values()]


def fit_association(
    record: ArrivalRecord,
    lat: NDArray,
    lon: NDArray,
    beacons: BeaconTable,
    info: FloatInfo,
    model: ModelConfig,
    position_sd_km: float,
) -> tuple[ModelConfig, dict[str, float]]:
    """`model` with multipath fraction and delay, echo fraction and clutter rate fitted at the
    track (lat, lon: one position per window of `record`), and a report of them."""
    sigma_e = float(np.hypot(model.toa_sigma_s, position_sd_km / KM_PER_S))
    fitted = model
    # The predictions at the track (arrival times, detection) do not change with the fitted
    # parameters: computed once.
    batches = _batches(record, lat, lon, beacons, info, dataclasses.replace(fitted, toa_sigma_s=sigma_e))
    for _ in range(ITERATIONS):
        e_model = dataclasses.replace(fitted, toa_sigma_s=sigma_e)
        first = delayed = delay_sum = echoes = echo_chances = 0.0
        p_clutter = [np.zeros(0)]  # per batch, (n K,)
        for b in batches:
            x = _expected(b, info, e_model, fitted, sigma_e)
            first += x.first
            delayed += x.delayed
            delay_sum += x.multipath_delay
            echoes += x.echoes
            delay_sum += x.echo_delay
            echo_chances += x.echo_chances
            p_clutter.append(x.p_clutter)
        eps = float(np.clip(delayed / max(first, 1e-9), MIN_FRACTION, 0.5))
        tau = float(np.clip(delay_sum / max(delayed + echoes, 1e-9), 5.0, 200.0))
        echo = float(np.clip(echoes / max(echo_chances, 1e-9), MIN_FRACTION, 0.5))
        clutter = max(fit_clutter_rate(np.concatenate(p_clutter), record, info), 0.05)
        fitted = dataclasses.replace(
            fitted, multipath_fraction=eps, multipath_delay_s=tau, echo_fraction=echo, clutter_rate=clutter
        )
    report = {
        "multipath_fraction": round(fitted.multipath_fraction, 4),
        "multipath_delay_s": round(fitted.multipath_delay_s, 2),
        "echo_fraction": round(fitted.echo_fraction, 4),
        "clutter_rate": round(fitted.clutter_rate, 3),
        "e_step_toa_sigma_s": round(sigma_e, 3),
    }
    return fitted, report


@dataclass(frozen=True)
class _Expectations:
    """One batch's E-step sums under the association marginals: first arrivals, delayed
    ones (multipath) and their summed delays, echoes and their delays from their beacon's
    first arrival, the echoes' chances (first arrivals whose echo would be stored), and
    each signal's clutter probability."""

    first: float
    delayed: float
    multipath_delay: float
    echoes: float
    echo_delay: float
    echo_chances: float
    p_clutter: NDArray[np.float64]


def _expected(b: _Batch, info: FloatInfo, e_model: ModelConfig, fitted: ModelConfig, sigma_e: float) -> _Expectations:
    """The E-step on one batch: the exact association's marginals (first arrival, echo,
    clutter) and P(delayed | residual) of each first arrival."""
    h = np.asarray(m.horizon_s(b.toa_s, info.max_signals, info.window_s))  # (n,)
    f = m.association_factors(
        b.mu_s, b.p_detect, b.toa_s, max_signals=info.max_signals, window_s=info.window_s, model=e_model
    )
    assoc = exact.associate(f.log_match, f.log_unheard, log_echo=f.log_echo)
    p_echo = assoc.p_echo if assoc.p_echo is not None else np.zeros_like(assoc.p_match)
    p_first = assoc.p_match - p_echo  # (n, s, K)
    resid = b.toa_s[:, None, :] - b.mu_s[:, :, None]
    p_delayed = 1.0 - direct_probability(resid, e_model)
    delay = np.clip(_delay_mean(resid, sigma_e, fitted.multipath_delay_s, fitted.multipath_delay_shape), 0.0, None)
    # An echo of beacon i at T_j is delayed from i's first arrival, taken at its expected
    # time under the marginals; its delay informs tau as multipath's does.
    heard = p_first.sum(axis=2)
    first_toa = np.einsum("nsk,nk->ns", p_first, b.toa_s) / np.where(heard > 0, heard, 1.0)
    echo_delay = np.clip(b.toa_s[:, None, :] - first_toa[:, :, None], 0.0, None)
    stored = m.delay_cdf(h[:, None] - b.toa_s, fitted)  # G(h - T_j)
    return _Expectations(
        first=p_first.sum(),
        delayed=float(np.sum(p_first * p_delayed)),
        multipath_delay=float(np.sum(p_first * p_delayed * delay)),
        echoes=p_echo.sum(),
        echo_delay=float(np.sum(p_echo * echo_delay)),
        echo_chances=float(np.sum(p_first * stored[:, None, :])),
        p_clutter=assoc.p_clutter.ravel(),
    )
