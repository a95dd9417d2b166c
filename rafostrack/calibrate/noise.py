"""Arrival-time noise and clutter, estimated from a first pass.

Multipath: maximum likelihood of the model's error density (`model.measurement.toa_logpdf`: a Gaussian
of sd sigma, mixed with an exponentially delayed copy for multipath, fraction eps, mean
delay tau) over eps and tau, on the residuals of confidently labelled arrivals after the
timing fit (`calibrate.kalman`, which gives sigma).

Clutter: the expected number of clutter signals over the time the windows could store
them. A window stores clutter on [0, h] (h = the last stored TOA when the window is full,
else the window's end), so with E_k the expected clutter count of window k (the sum of its
signals' clutter probabilities), lambda = sum_k E_k / sum_k (h_k / W).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize
from scipy.special import expit, logit

from ..config import ModelConfig
from ..domain import ArrivalRecord, FloatInfo
from ..model.measurement import horizon_s, toa_logpdf

# Nelder-Mead's tolerances (xatol in logit eps and log tau, fatol in log-likelihood).
TOLERANCE = (1e-4, 1e-6)


def fit_multipath(
    residual_s: NDArray, toa_sigma_s: float, model: ModelConfig, tolerance: tuple[float, float] = TOLERANCE
) -> tuple[float, float]:
    """(eps, tau) maximising sum log f(r) with sigma fixed at `toa_sigma_s` (the EM step
    of the timing fit: sigma itself comes from the Kalman smoother's marginal likelihood);
    eps in [1e-4, 0.3], tau in [8, 200] s (a delay shorter than a few sigma would be
    indistinguishable from the Gaussian core, and take part of it), to `tolerance`."""
    r = np.clip(np.asarray(residual_s, dtype=float), -300.0, 300.0)

    def unpack(p: NDArray) -> ModelConfig:
        return dataclasses.replace(
            model,
            toa_sigma_s=toa_sigma_s,
            multipath_fraction=float(np.clip(expit(p[0]), 1e-4, 0.3)),
            multipath_delay_s=float(np.clip(np.exp(p[1]), 8.0, 200.0)),
        )

    def cost(p: NDArray) -> float:
        return -float(np.sum(toa_logpdf(r, unpack(p))))

    start = np.array([logit(min(max(model.multipath_fraction, 0.02), 0.5)), np.log(model.multipath_delay_s)])
    xatol, fatol = tolerance
    best = minimize(cost, start, method="Nelder-Mead", options={"xatol": xatol, "fatol": fatol, "maxiter": 1000})
    fitted = unpack(best.x)
    return fitted.multipath_fraction, fitted.multipath_delay_s


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
    """The arrivals' direct-path weights for `kalman.fit`, multipath refitted by EM at each call."""

    def __init__(self, model: ModelConfig, tolerance: tuple[float, float] = TOLERANCE):
        self.model = model
        self.tolerance = tolerance

    def weight_of(self, residual_s: NDArray, toa_sigma_s: float) -> NDArray:
        """P(direct) of each residual, under multipath fitted to them (`fit_multipath`)."""
        eps, tau = fit_multipath(residual_s, toa_sigma_s, self.model, self.tolerance)
        self.model = dataclasses.replace(
            self.model, toa_sigma_s=toa_sigma_s, multipath_fraction=eps, multipath_delay_s=tau
        )
        return direct_probability(residual_s, self.model)
