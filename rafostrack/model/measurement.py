"""Measurement model: predicted arrivals and the association factors of one window.

For a float at X and time t, beacon i's signal arrives (paper section 2, with clock terms)
    mu_i(X, t) = offset_i + drift_i * days_i(t) + range(X, b_i) / c + clock(t),
with a TOA error density f (Gaussian with sd sigma, optionally mixed with a delayed copy
for multipath: a Gamma delay of mean tau and shape k = 1 (exponential) or 2, `model.kernels`).
The float stores the first r signals in its window [0, W]; clutter is a Poisson process of
rate lambda per window, uniform on [0, W].

With K stored TOAs T_1 < ... < T_K the likelihood is a sum over partial matchings M of
beacons to signals (paper eqs. 14-17):
    p(T | X) = Lambda^K e^{-Lambda h}
               * sum_M  prod_{(i,j) in M} w_ij  prod_{i unmatched} u_i,
    w_ij = Pd_i f(T_j - mu_i) / Lambda          (eq. 14 "matched" over eq. 15 clutter)
    u_i  = 1 - Pd_i + Pd_i P(t_i outside [0, h]) (eq. 14 "missing" + "late")
with Lambda = lambda / W the clutter intensity and h the horizon: h = T_K when the window
is full (K = r: anything later could not have been stored), h = W otherwise. The
`unranked` baseline (eq. 19) drops the ranking: u_i = 1 - Pd_i.

Echoes (our extension): a detected signal also arrives a second time, by a longer path,
with probability e (`echo_fraction`), after a delay of the multipath delay's law (mean tau =
`multipath_delay_s`, shape k = `multipath_delay_shape`); both are the source's. A beacon
may then take a pair of signals j < j': in the matching, a direct arrival without a stored
echo weighs w_ij (1 - e G(h - T_j)) (no echo, or one after the horizon), a pair
w_ij (1 - e G(h - T_j)) E_jj' with E_jj' = e g(T_j' - T_j) / (Lambda (1 - e G(h - T_j))),
g and G the delay's density and CDF (`echo_factors`). The echo factors depend on the
signals only, not on the particle.

Arrays are shaped (particles, beacons, signals) = (P, s, K).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..config import ModelConfig
from ..domain import BeaconTable, FloatInfo, elapsed_days
from .geodesy import ranges_about_centre_m
from .kernels import detection_kernel, factors_kernel, factors_kernel_threaded, toa_cdf_kernel, toa_logpdf_kernel
from .parallel import threaded


@dataclass(frozen=True)
class AssociationFactors:
    """Factors of one window, per particle: sum over matchings gives the likelihood."""

    log_match: NDArray[np.float64]  # (P, s, K): log w_ij
    log_unheard: NDArray[np.float64]  # (P, s): log u_i
    log_base: float | NDArray[np.float64]  # K log Lambda - Lambda h, shared by all particles (or (P,): a batch)
    log_echo: NDArray[np.float64] | None = None  # (K, K) or (P, K, K): log E_jj', the echo pair terms (None: none)


@dataclass(frozen=True)
class WindowBeacons:
    """The beacons transmitting during one window and their arrival delay terms."""

    index: NDArray[np.intp]  # rows of the beacon table
    lat: NDArray[np.float64]
    lon: NDArray[np.float64]
    delay_s: NDArray[np.float64]  # offset + drift * days + float clock offset
    sound_speed_m_s: NDArray[np.float64] | None = None  # per beacon (NaN: the model's)
    p_detect: NDArray[np.float64] | None = None
    detection_range_km: NDArray[np.float64] | None = None


def window_beacons(
    beacons: BeaconTable, info: FloatInfo, time: np.datetime64, index: NDArray[np.intp] | None = None
) -> WindowBeacons:
    """Beacons at `time` (the active ones, or the rows `index`) with the range-independent
    part of their arrival time.

    Source clock drift accrues from the beacon's `start` date, or from the float's launch
    when the beacon has none; the float clock offset is interpolated linearly in time.
    """
    if index is None:
        index = np.flatnonzero(beacons.active_at(time))
    epoch = np.where(np.isnat(beacons.start[index]), info.launch_time, beacons.start[index])
    days = elapsed_days(np.asarray(time), epoch)
    delay = beacons.offset_s[index] + beacons.drift_s_per_day[index] * days + info.clock_offset_s(time)
    per_beacon = [
        None if values is None else values[index]
        for values in (beacons.sound_speed_m_s, beacons.p_detect, beacons.detection_range_km)
    ]
    return WindowBeacons(index, beacons.lat[index], beacons.lon[index], delay, *per_beacon)


def _per_beacon(values: NDArray | None, default: float) -> NDArray | float:
    """Per-beacon values with NaN (or all, when None) replaced by the model's `default`."""
    return default if values is None else np.where(np.isnan(values), default, values)


def beacon_values(values: NDArray | None, default: float, s: int) -> NDArray[np.float64]:
    """`_per_beacon`'s values as an array of the window's s beacons."""
    return np.ascontiguousarray(np.broadcast_to(_per_beacon(values, default), s), dtype=np.float64)


def beacon_ranges_m(lat: NDArray, lon: NDArray, wb: WindowBeacons) -> NDArray[np.float64]:
    """Ranges (P, s) from particle positions (P,) to the window's beacons (about the cloud's
    centre, within `geodesy.EXPANSION_TOLERANCE_M` of the exact formula)."""
    return ranges_about_centre_m(lat, lon, wb.lat, wb.lon)


def predicted_toa_s(ranges_m: NDArray, wb: WindowBeacons, model: ModelConfig) -> NDArray[np.float64]:
    """Predicted arrival times mu_i = delay_i + range_i / c_i, shape (P, s) (c_i the beacon's
    sound speed where calibrated, else the model's)."""
    return wb.delay_s[None, :] + ranges_m / _per_beacon(wb.sound_speed_m_s, model.sound_speed_m_s)


def detection_prob(ranges_m: NDArray, wb: WindowBeacons, model: ModelConfig) -> NDArray[np.float64]:
    """Pd as a function of range: p_i / (1 + exp((range - R_i) / w)), the peak probability
    p_i and half range R_i per beacon where calibrated, else the model's (R = 0: no fall-off);
    ranges (P, s). Compiled (`kernels.detection_c`, which the window evidence's kernel shares)."""
    ranges = np.ascontiguousarray(np.atleast_2d(ranges_m), dtype=np.float64)
    s = ranges.shape[1]
    out = np.empty(ranges.shape)
    p_peak = beacon_values(wb.p_detect, model.p_detect, s)
    half_range_km = beacon_values(wb.detection_range_km, model.detection_range_km, s)
    detection_kernel(ranges, p_peak, half_range_km, float(model.detection_falloff_km), out)
    return out.reshape(np.shape(ranges_m))


def window_prediction(
    beacons: BeaconTable, info: FloatInfo, model: ModelConfig, lat: NDArray, lon: NDArray, time: np.datetime64
) -> tuple[WindowBeacons, NDArray[np.float64], NDArray[np.float64]]:
    """The window's active beacons, and for positions (lat, lon) their predicted arrival
    times and detection probabilities, each (P, s)."""
    wb = window_beacons(beacons, info, time)
    return (wb, *beacon_prediction(wb, model, lat, lon))


def beacon_prediction(
    wb: WindowBeacons, model: ModelConfig, lat: NDArray, lon: NDArray
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """For positions (lat, lon), the predicted arrival times and detection probabilities
    of a window's beacons `wb`, each (P, s)."""
    ranges = beacon_ranges_m(lat, lon, wb)
    return predicted_toa_s(ranges, wb, model), detection_prob(ranges, wb, model)


def toa_logpdf(resid_s: ArrayLike, model: ModelConfig) -> NDArray[np.float64]:
    """log f(r) for the TOA error r = T - mu: a Gaussian of sd sigma, mixed with a delayed
    copy (multipath) of fraction eps, its delay Gamma of mean tau and shape k
    (`model.kernels`, where the formulas are)."""
    return _elementwise(toa_logpdf_kernel, resid_s, model)


def toa_cdf(resid_s: ArrayLike, model: ModelConfig) -> NDArray[np.float64]:
    """F(r) = P(T - mu <= r) for the density of `toa_logpdf` (`model.kernels`)."""
    return _elementwise(toa_cdf_kernel, resid_s, model)


def _elementwise(kernel: Callable[..., None], resid_s: ArrayLike, model: ModelConfig) -> NDArray[np.float64]:
    """`kernel` (`toa_logpdf_kernel`, `toa_cdf_kernel`) of each residual, in its shape."""
    resid = np.asarray(resid_s, dtype=np.float64)
    out = np.empty(resid.shape)
    kernel(
        resid.reshape(-1),
        model.toa_sigma_s,
        model.multipath_fraction,
        model.multipath_delay_s,
        model.multipath_delay_shape,
        out.reshape(-1),
    )
    return out


def delay_log_shape(delay_s: NDArray, model: ModelConfig) -> NDArray[np.float64]:
    """log of the multipath (and echo) delay density's shape factor, (x^(k-1) / (k - 1)!)
    with x = d / theta: the density of a Gamma(k, theta = tau / k) delay d >= 0 is
    g(d) = exp(-x) / theta * x^(k-1) / (k - 1)! (0 for k = 1: an exponential delay)."""
    k = model.multipath_delay_shape
    if k == 1:
        return np.zeros(np.shape(delay_s))
    with np.errstate(divide="ignore"):
        return (k - 1) * np.log(np.clip(delay_s, 0.0, None) * (k / model.multipath_delay_s)) - math.lgamma(k)


def delay_cdf(delay_s: NDArray, model: ModelConfig) -> NDArray[np.float64]:
    """G(d) = P(delay <= d), 0 below 0: 1 - exp(-d / theta) sum_{n < k} (d / theta)^n / n!."""
    k, theta = model.multipath_delay_shape, model.multipath_delay_s / model.multipath_delay_shape
    x = np.clip(np.asarray(delay_s, dtype=np.float64), 0.0, None) / theta
    if k == 1:
        return -np.expm1(-x)
    return -np.expm1(-x + np.log1p(sum(x**n / math.factorial(n) for n in range(1, k))))


def multipath_delays(rng: np.random.Generator, model: ModelConfig, size: int | tuple[int, ...]) -> NDArray:
    """Draws of the multipath (and echo) delay, Gamma(k, tau / k) (tau * a standard
    exponential draw when k = 1)."""
    k = model.multipath_delay_shape
    return model.multipath_delay_s / k * rng.standard_gamma(k, size)


def clutter_intensity(model: ModelConfig, window_s: float) -> float:
    """Lambda = lambda / W: clutter signals per second of window."""
    return model.clutter_rate / window_s


def horizon_s(toa_s: NDArray, max_signals: int, window_s: float) -> float | NDArray[np.float64]:
    """Time after which an unstored signal may lie: last TOA if full, else window end; for
    a batch of windows with K signals each, (P, K), one per row."""
    toa = np.asarray(toa_s, dtype=np.float64)
    full = toa.shape[-1] >= max_signals
    if toa.ndim == 1:
        return float(toa[-1]) if full else window_s
    return toa[:, -1].copy() if full else np.full(len(toa), window_s)


@dataclass(frozen=True)
class SignalTerms:
    """A window's terms that depend on its signals alone, shared by every particle and
    beacon (module docstring): log Lambda, the horizon h, the shared term K log Lambda -
    Lambda h, and the echo terms (`echo_factors`: the per-signal factor (1, K) or (P, K),
    (0, K) without echoes, and log E_jj', None without)."""

    log_intensity: float
    horizon: float | NDArray[np.float64]
    log_base: float | NDArray[np.float64]
    no_echo: NDArray[np.float64]
    log_echo: NDArray[np.float64] | None


def signal_terms(toa_s: NDArray, *, max_signals: int, window_s: float, model: ModelConfig) -> SignalTerms:
    """The `SignalTerms` of a window's stored arrival times `toa_s` (K,), or (P, K) for a
    batch of windows (`association_factors`)."""
    lam = clutter_intensity(model, window_s)
    h = horizon_s(toa_s, max_signals, window_s)
    k = np.shape(toa_s)[-1]
    no_echo, log_echo = np.empty((0, k)), None
    if model.echo_fraction > 0 and k:  # the echo terms' per-signal part joins log w_ij in the kernel
        per_signal, log_echo = echo_factors(toa_s, h, lam, model)
        no_echo = np.atleast_2d(per_signal)
    return SignalTerms(float(np.log(lam)), h, k * np.log(lam) - lam * h, no_echo, log_echo)


def association_factors(
    mu_s: NDArray,
    p_detect: NDArray,
    toa_s: NDArray,
    *,
    max_signals: int,
    window_s: float,
    model: ModelConfig,
    ranked: bool = True,
    source_log_ratio: NDArray | None = None,
    signals: SignalTerms | None = None,
) -> AssociationFactors:
    """The window's factors w_ij, u_i and the shared term (see module docstring).

    `toa_s` (K,), or (P, K) for a batch of windows with the same number of beacons and K signals,
    one window per particle (the shared term and echo terms then have a row per particle).
    `ranked=False` gives the unranked baseline of eq. (19): an unheard beacon costs
    1 - Pd whatever its predicted arrival. `source_log_ratio` (K,): per signal, evidence
    that it came from a source rather than clutter (`rafostrack.likelihoods.quality`: its correlation
    height), added to every term that gives it to a source (w_ij, and E_jj' for an echo).
    `signals`: the window's `signal_terms`, when the caller keeps them from one set of
    particles to the next.
    """
    if signals is None:
        signals = signal_terms(toa_s, max_signals=max_signals, window_s=window_s, model=model)
    mu = np.ascontiguousarray(mu_s, dtype=np.float64)
    n, s = mu.shape
    k = np.shape(toa_s)[-1]
    log_match, log_unheard = np.empty((n, s, k)), np.empty((n, s))
    kernel = factors_kernel_threaded if threaded(n) else factors_kernel
    kernel(
        mu,
        np.ascontiguousarray(np.broadcast_to(p_detect, mu.shape), dtype=np.float64),
        np.ascontiguousarray(np.atleast_2d(toa_s), dtype=np.float64),
        model.toa_sigma_s,
        model.multipath_fraction,
        model.multipath_delay_s,
        model.multipath_delay_shape,
        signals.log_intensity,
        np.atleast_1d(np.asarray(signals.horizon, dtype=np.float64)),
        ranked,
        signals.no_echo,
        log_match,
        log_unheard,
    )
    log_echo = signals.log_echo
    if source_log_ratio is not None and k:
        log_match = log_match + source_log_ratio[None, None, :]
        log_echo = None if log_echo is None else log_echo + source_log_ratio[None, :]
    return AssociationFactors(log_match, log_unheard, signals.log_base, log_echo)


def echo_factors(toa_s: NDArray, horizon: float | NDArray, lam: float, model: ModelConfig) -> tuple[NDArray, NDArray]:
    """The echo terms of one window, shared by every particle and beacon (module docstring):
    log(1 - e G(h - T_j)) per signal, folded into the match factor of a direct arrival
    without a stored echo, and log E_jj' = log(e g(T_j' - T_j) / Lambda) - log(1 - e G(h - T_j))
    for j < j' (-inf elsewhere), with g the delay density (`delay_log_shape`) and G its CDF
    (`delay_cdf`). Shapes (K,) and (K, K); for a batch of windows (`toa_s` (P, K), `horizon`
    (P,)), a row each."""
    eps = model.echo_fraction
    toa = np.asarray(toa_s)
    k = toa.shape[-1]
    no_echo = np.log1p(-eps * delay_cdf(np.asarray(horizon)[..., None] - toa, model))
    delay = np.clip(toa[..., None, :] - toa[..., :, None], 0.0, None)  # (j, j'): T_j' - T_j
    later = np.triu(np.ones((k, k), dtype=bool), k=1)
    theta = model.multipath_delay_s / model.multipath_delay_shape
    with np.errstate(divide="ignore"):
        log_g = np.log(eps / theta) - delay / theta + delay_log_shape(delay, model)  # log e g(d)
    log_pair = np.where(later, log_g - np.log(lam), -np.inf)
    return no_echo, log_pair - no_echo[..., :, None]


def labeled_loglik(
    mu_s: NDArray, toa_s: NDArray, label_index: NDArray, model: ModelConfig, sigma_scale: NDArray | None = None
) -> NDArray:
    """Hand-labelled likelihood (eq. 20): prod over labelled TOAs of f(T_j - mu_{R_j}).

    `label_index[j]` is the column of `mu_s` of the TOA's beacon, or -1 for clutter,
    which contributes nothing. `sigma_scale[j]` widens TOA j's error density to
    f(r / s) / s (1 = as configured).
    """
    used = label_index >= 0
    if not used.any():
        return np.zeros(mu_s.shape[0])
    scale = np.ones(int(used.sum())) if sigma_scale is None else np.asarray(sigma_scale)[used]
    resid = toa_s[used][None, :] - mu_s[:, label_index[used]]
    return (toa_logpdf(resid / scale, model) - np.log(scale)).sum(axis=1)


def predicted_arrivals(
    times: NDArray[np.datetime64],
    lat: NDArray,
    lon: NDArray,
    beacons: BeaconTable,
    info: FloatInfo,
    model: ModelConfig,
) -> NDArray[np.float64]:
    """Predicted TOA (s) of every beacon along a track, shape (len(times), n_beacons).

    NaN where the beacon is not active at that time.
    """
    out = np.full((len(times), len(beacons)), np.nan)
    for k, t in enumerate(times):
        wb = window_beacons(beacons, info, t)
        ranges = beacon_ranges_m(np.atleast_1d(lat[k]), np.atleast_1d(lon[k]), wb)
        out[k, wb.index] = predicted_toa_s(ranges, wb, model)[0]
    return out
