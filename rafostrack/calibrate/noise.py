"""Arrival-time noise and clutter, estimated from a first pass.

Multipath: maximum likelihood of the model's error density (`model.measurement.toa_logpdf`: a Gaussian
of sd sigma, mixed with an exponentially delayed copy for multipath, fraction eps, mean
delay tau) over eps and tau, on the residuals of confidently labelled arrivals after the
timing fit (`calibrate.kalman`, which gives sigma): by Nelder-Mead (`fit_multipath`), or by
EM (`fit_multipath_em`, to the same maximum; the mission's array fit, which refits at every
step from the step before). EM's steps, with q_n = 1 - P(direct | r_n)
and the delay's posterior mean E[d | r_n] (`delay_posterior_mean_s`), are

    eps' = mean_n q_n,    tau' = sum_n q_n E[d | r_n] / sum_n q_n

(the Gamma delay's scale for its fixed shape k, times k, is the weighted mean delay).

Clutter: the expected number of clutter signals over the time the windows could store
them. A window stores clutter on [0, h] (h = the last stored TOA when the window is full,
else the window's end), so with E_k the expected clutter count of window k (the sum of its
signals' clutter probabilities), lambda = sum_k E_k / sum_k (h_k / W).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize
from scipy.special import expit, log_ndtr, logit

from ..config import ModelConfig
from ..domain import ArrivalRecord, FloatInfo
from ..model.measurement import horizon_s, toa_logpdf

# Nelder-Mead's tolerances (xatol in logit eps and log tau, fatol in log-likelihood).
TOLERANCE = (1e-4, 1e-6)
EPS_BOUNDS, TAU_BOUNDS_S = (1e-4, 0.3), (8.0, 200.0)
RESIDUAL_CLIP_S = 300.0
EM_ITERATIONS = 200
_LOG_SQRT_2PI = 0.5 * np.log(2.0 * np.pi)
# (residuals, sigma, the model with the previous fit's eps and tau, tolerance) -> (eps, tau)
MultipathFit = Callable[[NDArray, float, ModelConfig, tuple[float, float]], tuple[float, float]]


def fit_multipath(
    residual_s: NDArray, toa_sigma_s: float, model: ModelConfig, tolerance: tuple[float, float] = TOLERANCE
) -> tuple[float, float]:
    """(eps, tau) maximising sum log f(r) with sigma fixed at `toa_sigma_s` (the EM step
    of the timing fit: sigma itself comes from the Kalman smoother's marginal likelihood);
    eps in [1e-4, 0.3], tau in [8, 200] s (a delay shorter than a few sigma would be
    indistinguishable from the Gaussian core, and take part of it), to `tolerance`."""
    r = _clipped(residual_s)

    def unpack(p: NDArray) -> ModelConfig:
        return dataclasses.replace(
            model,
            toa_sigma_s=toa_sigma_s,
            multipath_fraction=float(np.clip(expit(p[0]), *EPS_BOUNDS)),
            multipath_delay_s=float(np.clip(np.exp(p[1]), *TAU_BOUNDS_S)),
        )

    def cost(p: NDArray) -> float:
        return -float(np.sum(toa_logpdf(r, unpack(p))))

    start = np.array([logit(_start_eps(model)), np.log(model.multipath_delay_s)])
    xatol, fatol = tolerance
    best = minimize(cost, start, method="Nelder-Mead", options={"xatol": xatol, "fatol": fatol, "maxiter": 1000})
    fitted = unpack(best.x)
    return fitted.multipath_fraction, fitted.multipath_delay_s


def _clipped(residual_s: NDArray) -> NDArray[np.float64]:
    """Residuals as both fits take them: within +-`RESIDUAL_CLIP_S` (an arrival further off
    counts as one at that edge)."""
    return np.clip(np.asarray(residual_s, dtype=float), -RESIDUAL_CLIP_S, RESIDUAL_CLIP_S)


def _start_eps(model: ModelConfig) -> float:
    """Where a fit of eps starts: the model's, but in [0.02, 0.5] (from nearer 0 it would
    crawl: the delayed copy then explains almost no residual)."""
    return min(max(model.multipath_fraction, 0.02), 0.5)


def fit_multipath_em(
    residual_s: NDArray, toa_sigma_s: float, model: ModelConfig, tolerance: tuple[float, float] = TOLERANCE
) -> tuple[float, float]:
    """`fit_multipath`'s maximum by EM (module docstring), each iterate within its bounds:
    about a quarter of Nelder-Mead's time from a start near the maximum (a previous fit's).
    Stops where the distance left to the fixed point, estimated from the contraction of the
    steps (|step| rho / (1 - rho), rho the ratio of the last two steps; from the third step
    on: the first, from a start far off, contracts faster than the rest), is within the
    `tolerance`'s first entry in logit eps and log tau."""
    r = _clipped(residual_s)
    current = dataclasses.replace(
        model,
        toa_sigma_s=toa_sigma_s,
        multipath_fraction=float(np.clip(_start_eps(model), *EPS_BOUNDS)),
        multipath_delay_s=float(np.clip(model.multipath_delay_s, *TAU_BOUNDS_S)),
    )
    last_step = np.inf
    for iteration in range(EM_ITERATIONS):
        q = 1.0 - direct_probability(r, current)
        eps = float(np.clip(np.mean(q), *EPS_BOUNDS))
        tau = float(np.clip(np.sum(q * delay_posterior_mean_s(r, current)) / max(np.sum(q), 1e-300), *TAU_BOUNDS_S))
        step = max(abs(logit(eps) - logit(current.multipath_fraction)), abs(np.log(tau / current.multipath_delay_s)))
        current = dataclasses.replace(current, multipath_fraction=eps, multipath_delay_s=tau)
        rho = min(step / last_step, 0.99)
        if step == 0.0 or (iteration >= 2 and step * rho / (1.0 - rho) <= tolerance[0]):
            break
        last_step = step
    return current.multipath_fraction, current.multipath_delay_s


def delay_posterior_mean_s(residual_s: NDArray, model: ModelConfig) -> NDArray[np.float64]:
    """E[d | r, delayed]: the multipath delay's posterior mean given an arrival's residual r,
    were it delayed. The posterior is d^(k-1) e^(-d / theta) phi((r - d) / sigma) on d > 0,
    a Gaussian N(m, sigma^2) (m = r - sigma^2 / theta = sigma u) truncated to d > 0 and, for
    k = 2, times d; with lambda = phi(u) / Phi(u) (the truncated moments),

        k = 1: E[d | r] = sigma (u + lambda),
        k = 2: E[d | r] = sigma (u^2 + 1 + u lambda) / (u + lambda)."""
    sigma, shape = model.toa_sigma_s, model.multipath_delay_shape
    u = np.asarray(residual_s, dtype=float) / sigma - shape * sigma / model.multipath_delay_s
    lam = np.exp(-0.5 * u * u - _LOG_SQRT_2PI - log_ndtr(u))
    if shape == 1:
        return sigma * (u + lam)
    return sigma * (u * u + 1.0 + u * lam) / (u + lam)


def direct_probability(residual_s: NDArray, model: ModelConfig) -> NDArray[np.float64]:
    """P(an arrival came by the direct path | its residual): the Gaussian component's share
    of the error density, (1 - eps) N(r; 0, sigma^2) / f(r)."""
    direct = dataclasses.replace(model, multipath_fraction=0.0)
    return np.exp(np.log1p(-model.multipath_fraction) + toa_logpdf(residual_s, direct) - toa_logpdf(residual_s, model))


def fit_clutter_rate(p_clutter: NDArray, record: ArrivalRecord, info: FloatInfo) -> float:
    """Clutter signals per window (module docstring), from every stored TOA's clutter
    probability `p_clutter`."""
    expected = float(np.sum(p_clutter))
    exposure = clutter_exposure(record, info)
    return expected / exposure if exposure > 0 else float("nan")


def clutter_exposure(record: ArrivalRecord, info: FloatInfo) -> float:
    """The windows' time that could store clutter, in windows: sum_k h_k / W (module docstring)."""
    return sum(float(horizon_s(w.toa_s, info.max_signals, info.window_s)) / info.window_s for w in record.windows)


class MultipathEM:
    """The arrivals' direct-path weights for `kalman.fit`, multipath refitted at each call
    (`fit`: `fit_multipath`, or `fit_multipath_em`) from the previous call's."""

    def __init__(
        self, model: ModelConfig, tolerance: tuple[float, float] = TOLERANCE, fit: MultipathFit = fit_multipath
    ):
        self.model = model
        self.tolerance = tolerance
        self.fit = fit

    def weight_of(self, residual_s: NDArray, toa_sigma_s: float) -> NDArray:
        """P(direct) of each residual, under multipath fitted to them (`fit`)."""
        eps, tau = self.fit(residual_s, toa_sigma_s, self.model, self.tolerance)
        self.model = dataclasses.replace(
            self.model, toa_sigma_s=toa_sigma_s, multipath_fraction=eps, multipath_delay_s=tau
        )
        return direct_probability(residual_s, self.model)
