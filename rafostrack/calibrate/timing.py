"""The timing nuisances of a record, fitted jointly with the positions (a bundle adjustment).

From confidently labelled arrivals T (window w, beacon i) and a first-pass track, the fit
finds small changes to every window's position and to the parameters that shift arrival
times:

    T = offset_i + a_i + (drift_i + d_i) days_i(t) + clock(t) + delta(t)
        + R(x_w + dx_w, b_i) (s + ds_i) + e,

with s = 1 / c the effective slowness shared by all beacons, ds_i a beacon's own deviation
(its paths cross other water), a_i and d_i corrections to a beacon's transmission offset and
clock drift, and delta(t) a smooth (piecewise linear, knots every `knot_days`) residual of
the float clock beyond the linear launch-to-end model. Linearised about the current values,
this is a weighted least-squares problem with Gaussian priors on every parameter (they keep
a window seen by two beacons, or a beacon heard ten times, from taking up what belongs to
others); the window offsets dx_w enter as 2x2 blocks and are eliminated (Schur complement),
so the cost grows linearly with the record. Each arrival is weighted by the probability that
it came by the direct path under the model's error density (Gaussian plus a delayed
multipath copy, whose sigma, fraction and delay are refitted from the residuals at every
iteration): an EM algorithm, in which multipath and mislabelled arrivals do not pull the
fit. Five Gauss-Newton iterations.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import pandas as pd
from numpy.typing import NDArray
from scipy import sparse
from scipy.sparse.linalg import splu

from ..config import ModelConfig
from ..domain import BeaconTable, FloatInfo, elapsed_days
from ..geodesy import displace, local_offsets_km, range_m
from ..model import toa_logpdf
from .noise import fit_toa_noise

NS_PER_DAY = 86400e9


@dataclass(frozen=True)
class Arrivals:
    """Confidently labelled arrivals with the first-pass position of their window."""

    window: NDArray[np.intp]  # index into the windows below
    beacon: NDArray[np.intp]  # beacon-table row
    toa_s: NDArray[np.float64]
    time: NDArray[np.datetime64]  # per window
    lat: NDArray[np.float64]  # per window
    lon: NDArray[np.float64]
    sd_km: NDArray[np.float64]  # per window, the first pass's posterior sd
    anchored: NDArray[np.bool_]  # per window: a position fix (launch, end), not a first-pass estimate


@dataclass(frozen=True)
class TimingPriors:
    """Prior sds of the timing parameters (and the clock knots' spacing)."""

    sound_speed_m_s: float = 40.0  # of the shared effective sound speed
    beacon_sound_speed_m_s: float = 2.0  # of a beacon's deviation from it
    offset_s: float = 1.5
    drift_s_per_day: float = 0.02
    clock_s: float = 3.0
    clock_end_s: float = 0.5  # at launch and end, where the float's clock was measured
    knot_days: float = 10.0
    # The corrected track: each position within this many first-pass sds, and smooth, its
    # acceleration ~ N(0, (acceleration_sd / sqrt(days between windows))^2) per axis
    # (an eddy velocity of sd sigma and time scale T gives sigma sqrt(2 / T), ~2.5 km/day^1.5).
    position_sd_factor: float = 10.0
    acceleration_sd: float = 3.0


@dataclass(frozen=True)
class TimingFit:
    sound_speed_m_s: float
    beacon_sound_speed_m_s: NDArray[np.float64]  # per beacon row (the shared one where unheard)
    offset_s: NDArray[np.float64]  # per beacon row: correction to add
    drift_s_per_day: NDArray[np.float64]
    clock_knots: NDArray[np.datetime64]
    clock_s: NDArray[np.float64]
    residual_s: NDArray[np.float64]  # per arrival, after the fit
    heard: NDArray[np.bool_]  # per beacon row: any arrival used
    track: pd.DataFrame  # time, lat, lon of the fitted (corrected, smooth) positions


def _clock_basis(times: NDArray[np.datetime64], knots: NDArray[np.datetime64]) -> NDArray[np.float64]:
    """(n, K) hat functions of piecewise-linear interpolation between the knots."""
    t = times.astype("datetime64[ns]").astype(np.int64).astype(float)
    k = knots.astype("datetime64[ns]").astype(np.int64).astype(float)
    eye = np.eye(len(k))
    return np.column_stack([np.interp(t, k, eye[j]) for j in range(len(k))])


def _knots(info: FloatInfo, times: NDArray[np.datetime64], knot_days: float) -> NDArray[np.datetime64]:
    start = np.datetime64(info.launch_time).astype("datetime64[ns]")
    end = np.datetime64(info.end_time if info.has_end_fix else times.max()).astype("datetime64[ns]")
    n = max(2, int(np.ceil(float((end - start) / np.timedelta64(1, "ns")) / NS_PER_DAY / knot_days)) + 1)
    return start + (np.linspace(0.0, 1.0, n) * float((end - start) / np.timedelta64(1, "ns"))).astype("timedelta64[ns]")


def _smoothness(arrivals: Arrivals, acceleration_sd: float) -> tuple[sparse.csr_matrix, NDArray, NDArray]:
    """The acceleration rows of the track: for each inner window w and axis, the second
    difference (x_{w+1} - x_w) / d2 - (x_w - x_{w-1}) / d1 over (d1 + d2) / 2, as a sparse
    matrix S on the flattened offsets dx (n_win * 2), the first pass's own value of it (in w's
    tangent plane), and each row's prior sd."""
    n = len(arrivals.time)
    if n < 3:
        return sparse.csr_matrix((0, 2 * n)), np.zeros(0), np.zeros(0)
    days = elapsed_days(arrivals.time, arrivals.time[0])
    d1, d2 = np.diff(days)[:-1], np.diff(days)[1:]
    mid = 0.5 * (d1 + d2)
    c_prev, c_next = 1.0 / (d1 * mid), 1.0 / (d2 * mid)
    c_mid = -(c_prev + c_next)
    w = np.arange(1, n - 1)
    rows, cols, vals = [], [], []
    for axis in range(2):
        row = 2 * (w - 1) + axis
        for offset, coef in ((-1, c_prev), (0, c_mid), (1, c_next)):
            rows.append(row)
            cols.append(2 * (w + offset) + axis)
            vals.append(coef)
    smooth = sparse.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(2 * (n - 2), 2 * n)
    )
    e_prev, n_prev = local_offsets_km(arrivals.lat[w - 1], arrivals.lon[w - 1], arrivals.lat[w], arrivals.lon[w])
    e_next, n_next = local_offsets_km(arrivals.lat[w + 1], arrivals.lon[w + 1], arrivals.lat[w], arrivals.lon[w])
    own = np.empty(2 * (n - 2))
    own[0::2] = c_prev * e_prev + c_next * e_next
    own[1::2] = c_prev * n_prev + c_next * n_next
    sd = np.repeat(acceleration_sd / np.sqrt(mid), 2)
    return smooth, sd, own


def fit_timing(
    arrivals: Arrivals,
    beacons: BeaconTable,
    info: FloatInfo,
    model: ModelConfig,
    priors: TimingPriors = TimingPriors(),
    iterations: int = 5,
    fix_sound_speed: bool = False,
) -> tuple[TimingFit, ModelConfig]:
    """Fit the timing parameters and window offsets (module docstring), and the TOA noise
    (sigma, multipath fraction and delay) with them; return the fit and `model` with the
    fitted noise. `fix_sound_speed`: the shared sound speed is `model`'s, not fitted."""
    sound_speed_m_s = model.sound_speed_m_s
    s_beacons, n_win = len(beacons), len(arrivals.time)
    knots = _knots(info, arrivals.time, priors.knot_days)
    n_knots = len(knots)
    # Global parameter layout: [ds, ds_i (s_beacons), a_i, d_i, clock knots].
    g_ds, g_dsi, g_a, g_d, g_clk = 0, 1, 1 + s_beacons, 1 + 2 * s_beacons, 1 + 3 * s_beacons
    n_g = g_clk + n_knots
    s0 = 1.0 / sound_speed_m_s
    prior_sd = np.concatenate(
        [
            [priors.sound_speed_m_s * s0 * s0],
            np.full(s_beacons, priors.beacon_sound_speed_m_s * s0 * s0),
            np.full(s_beacons, priors.offset_s),
            np.full(s_beacons, priors.drift_s_per_day),
            np.full(n_knots, priors.clock_s),
        ]
    )
    prior_sd[g_clk] = prior_sd[g_clk + n_knots - 1] = priors.clock_end_s if info.has_end_fix else priors.clock_s
    prior_sd[g_clk] = priors.clock_end_s
    if fix_sound_speed:  # estimated elsewhere (the record's likelihood): only per-beacon deviations here
        prior_sd[g_ds] = 1e-12
    theta = np.zeros(n_g)
    dx = np.zeros((n_win, 2))
    w_idx, b_idx = arrivals.window, arrivals.beacon
    clock_basis = _clock_basis(arrivals.time, knots)[w_idx]
    epoch = np.where(np.isnat(beacons.start[b_idx]), info.launch_time, beacons.start[b_idx])
    days = elapsed_days(arrivals.time[w_idx], epoch)
    base_delay = (
        beacons.offset_s[b_idx] + beacons.drift_s_per_day[b_idx] * days + info.clock_offset_s(arrivals.time[w_idx])
    )

    def predicted() -> tuple[NDArray, NDArray, NDArray, NDArray]:
        """Arrival times at the current parameters, and the ranges, range gradients (m per
        km east / north, central differences of 100 m) and slownesses behind them."""
        lat, lon = displace(arrivals.lat, arrivals.lon, dx[:, 0], dx[:, 1])
        at_lat, at_lon = lat[w_idx], lon[w_idx]
        blat, blon = beacons.lat[b_idx], beacons.lon[b_idx]
        r = range_m(at_lat, at_lon, blat, blon)
        grad = np.column_stack(
            [
                (range_m(*displace(at_lat, at_lon, 0.1, 0.0), blat, blon)
                 - range_m(*displace(at_lat, at_lon, -0.1, 0.0), blat, blon)) / 0.2,
                (range_m(*displace(at_lat, at_lon, 0.0, 0.1), blat, blon)
                 - range_m(*displace(at_lat, at_lon, 0.0, -0.1), blat, blon)) / 0.2,
            ]
        )  # fmt: skip
        slow = s0 + theta[g_ds] + theta[g_dsi + b_idx]
        mu = base_delay + theta[g_a + b_idx] + theta[g_d + b_idx] * days + clock_basis @ theta[g_clk:] + r * slow
        return mu, r, grad, slow

    n_obs, n_x = len(w_idx), 2 * n_win
    obs = np.arange(n_obs)
    smooth_coef, smooth_sd, plane_acc = _smoothness(arrivals, priors.acceleration_sd)
    position_sd = np.repeat(
        np.where(arrivals.anchored, arrivals.sd_km, np.maximum(arrivals.sd_km, 0.5) * priors.position_sd_factor), 2
    )

    def objective(noise: ModelConfig) -> float:
        """The negative log posterior (up to a constant): arrivals under the error density,
        the priors, the track's smoothness."""
        residual = arrivals.toa_s - predicted()[0]
        acc = plane_acc + smooth_coef @ dx.ravel()
        return float(
            -np.sum(toa_logpdf(residual, noise))
            + 0.5 * np.sum((theta / prior_sd) ** 2)
            + 0.5 * np.sum((dx.ravel() / position_sd) ** 2)
            + 0.5 * np.sum((acc / smooth_sd) ** 2)
        )

    for _ in range(iterations):
        mu, r, grad, slow = predicted()
        residual = arrivals.toa_s - mu
        model = _noise_model(residual, model)
        before = objective(model)
        w = direct_probability(residual, model) / model.toa_sigma_s**2
        jx = sparse.csr_matrix(
            ((grad * slow[:, None]).ravel(), (np.repeat(obs, 2), (2 * w_idx[:, None] + np.arange(2)).ravel())),
            shape=(n_obs, n_x),
        )
        jg = np.zeros((n_obs, n_g))
        jg[:, g_ds] = r
        jg[obs, g_dsi + b_idx] = r
        jg[obs, g_a + b_idx] = 1.0
        jg[obs, g_d + b_idx] = days
        jg[:, g_clk:] = clock_basis
        # Smoothness of the corrected track: its acceleration (second differences, per axis)
        # a = S (x_first_pass + dx) ~ N(0, sd^2), S sparse with rows over three windows.
        acc = plane_acc + smooth_coef @ dx.ravel()
        weight_s = 1.0 / smooth_sd**2
        nxx = (jx.T @ sparse.diags(w) @ jx + smooth_coef.T @ sparse.diags(weight_s) @ smooth_coef
               + sparse.diags(1.0 / position_sd**2))  # fmt: skip
        nxg = jx.T @ (jg * w[:, None])
        ngg = (jg * w[:, None]).T @ jg + np.diag(1.0 / prior_sd**2)
        bx = jx.T @ (w * residual) - smooth_coef.T @ (weight_s * acc) - dx.ravel() / position_sd**2
        bg = jg.T @ (w * residual) - theta / prior_sd**2
        normal = sparse.bmat([[nxx, sparse.csr_matrix(nxg)], [sparse.csr_matrix(nxg.T), sparse.csr_matrix(ngg)]])
        solver = splu(normal.tocsc())
        step = solver.solve(np.concatenate([bx, bg]))
        # Damped: halve the Gauss-Newton step until the objective falls (the model is not
        # linear in the positions far from the first pass).
        for _ in range(6):
            dx += step[:n_x].reshape(n_win, 2)
            theta += step[n_x:]
            if objective(model) <= before:
                break
            dx -= step[:n_x].reshape(n_win, 2)
            theta -= step[n_x:]
            step = 0.5 * step
        else:
            break
    residual = arrivals.toa_s - predicted()[0]
    fitted_lat, fitted_lon = displace(arrivals.lat, arrivals.lon, dx[:, 0], dx[:, 1])
    heard = np.bincount(b_idx, minlength=s_beacons) > 0
    slowness = s0 + theta[g_ds] + np.where(heard, theta[g_dsi : g_dsi + s_beacons], 0.0)
    fit = TimingFit(
        sound_speed_m_s=float(1.0 / (s0 + theta[g_ds])),
        beacon_sound_speed_m_s=1.0 / slowness,
        offset_s=np.where(heard, theta[g_a : g_a + s_beacons], 0.0),
        drift_s_per_day=np.where(heard, theta[g_d : g_d + s_beacons], 0.0),
        clock_knots=knots,
        clock_s=theta[g_clk:],
        residual_s=residual,
        heard=heard,
        track=pd.DataFrame({"time": arrivals.time, "lat": fitted_lat, "lon": fitted_lon}),
    )
    # The fitted positions and parameters take up some of the residuals' spread: sigma from
    # the residuals alone is too small by sqrt((n - p) / n), p = tr(H) the effective number
    # of parameters of the weighted fit (H = J N^-1 J^T W), estimated with Hutchinson's
    # trace estimator (E[z^T H z] = tr H for z of random signs).
    noise = _noise_model(residual, model)
    jac = sparse.hstack([jx, sparse.csr_matrix(jg)]).tocsr()
    probes = np.random.default_rng(0).choice([-1.0, 1.0], size=(16, n_obs))  # fixed: a deterministic estimate
    p_eff = float(np.mean([z @ (jac @ solver.solve(jac.T @ (w * z))) for z in probes]))
    n_direct = float(np.sum(direct_probability(residual, noise)))
    inflate = np.sqrt(n_direct / max(n_direct - p_eff, 0.25 * n_direct))
    return fit, dataclasses.replace(noise, toa_sigma_s=noise.toa_sigma_s * inflate)


def direct_probability(residual_s: NDArray, model: ModelConfig) -> NDArray[np.float64]:
    """P(an arrival came by the direct path | its residual): the Gaussian component's share
    of the error density, (1 - eps) N(r; 0, sigma^2) / f(r)."""
    direct = dataclasses.replace(model, multipath_fraction=0.0)
    return np.exp(np.log1p(-model.multipath_fraction) + toa_logpdf(residual_s, direct) - toa_logpdf(residual_s, model))


def _noise_model(residual_s: NDArray, model: ModelConfig) -> ModelConfig:
    """`model` with sigma, eps and tau fitted to the residuals (`noise.fit_toa_noise`), the
    multipath fraction kept above 1e-3 so that no residual gets full weight by default."""
    sigma, eps, tau = fit_toa_noise(np.clip(residual_s, -300.0, 300.0), model)
    return dataclasses.replace(model, toa_sigma_s=sigma, multipath_fraction=max(eps, 1e-3), multipath_delay_s=tau)
