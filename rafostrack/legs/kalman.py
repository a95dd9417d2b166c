"""The Kalman baseline: a constant-velocity linear-Gaussian model with EM-learnt parameters.

State x = (east, north, v_east, v_north), measured position y = H x + e, e ~ N(0, R);
between times t_{k-1} and t_k (any spacing) a continuous white-noise acceleration of
intensity q:
    x_k = F(dt) x_{k-1} + w_k,  F = [[I, dt I], [0, I]],
    w_k ~ N(0, q Qt(dt)),  Qt = [[dt^3/3, dt^2/2], [dt^2/2, dt]] (x) I_2.
`kalman_filter` (with missing measurements as NaN rows), `rts_smoother` (Rauch-Tung-
Striebel, with the lag-one covariances EM needs) and `em_cv`: expectation-maximisation of
q, R (full 2x2) and the initial mean (Shumway & Stoffer's EM with A, C fixed by the
physics): each M step is closed form,
    q = sum_k tr(Qt_k^{-1} E[(x_k - F_k x_{k-1})(...)^T]) / (4 (N - 1)),
    R = mean over measured k of E[(y_k - H x_k)(...)^T],  x0 = E[x_0 | y].
The paper used Murphy's MATLAB Kalman toolbox, whose `learn_kalman` fits every matrix of
the model by the same EM; we keep the constant-velocity structure (a free 4x4 transition
fitted to a few dozen positions is not identified) and learn the noise levels.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

H = np.hstack([np.eye(2), np.zeros((2, 2))])
MIN_VARIANCE = 1e-8
EYE4 = np.eye(4)


@dataclass(frozen=True)
class CVParams:
    q: float  # acceleration noise intensity (length^2 / time^3)
    r: NDArray[np.float64]  # (2, 2) measurement covariance
    x0: NDArray[np.float64]  # (4,) initial mean at the first time
    p0: NDArray[np.float64]  # (4, 4) initial covariance


@dataclass(frozen=True)
class Filtered:
    pred_mean: NDArray[np.float64]  # (n, 4) E[x_k | y_1..k-1]
    pred_cov: NDArray[np.float64]  # (n, 4, 4)
    mean: NDArray[np.float64]  # (n, 4) E[x_k | y_1..k]
    cov: NDArray[np.float64]
    loglik: float


@dataclass(frozen=True)
class Smoothed:
    mean: NDArray[np.float64]  # (n, 4) E[x_k | all]
    cov: NDArray[np.float64]
    cross: NDArray[np.float64]  # (n, 4, 4) Cov(x_k, x_{k-1} | all); cross[0] unused


def transition(dt: NDArray) -> tuple[NDArray, NDArray]:
    """F (n, 4, 4) and Qt (n, 4, 4) for steps dt (n,)."""
    dt = np.asarray(dt, dtype=float)
    n = len(dt)
    f = np.tile(np.eye(4), (n, 1, 1))
    f[:, 0, 2] = f[:, 1, 3] = dt
    block = np.stack([np.stack([dt**3 / 3, dt**2 / 2], -1), np.stack([dt**2 / 2, dt], -1)], -2)
    return f, np.einsum("nij,kl->nikjl", block, np.eye(2)).reshape(n, 4, 4)


def _qt_inverse(dt: NDArray) -> NDArray:
    """Qt(dt)^{-1}: per axis [[12/dt^3, -6/dt^2], [-6/dt^2, 4/dt]]."""
    block = np.stack([np.stack([12 / dt**3, -6 / dt**2], -1), np.stack([-6 / dt**2, 4 / dt], -1)], -2)
    return np.einsum("nij,kl->nikjl", block, np.eye(2)).reshape(len(dt), 4, 4)


def kalman_filter(times: NDArray, y: NDArray, params: CVParams) -> Filtered:
    """The filter over `times` (n,); rows of `y` (n, 2) that are NaN are not measured."""
    n = len(times)
    f, qt = transition(np.diff(times))
    pm, pc = np.empty((n, 4)), np.empty((n, 4, 4))
    m_all, c_all = np.empty((n, 4)), np.empty((n, 4, 4))
    m, c = params.x0.astype(float), params.p0.astype(float)
    loglik = 0.0
    for k in range(n):
        if k:
            m = f[k - 1] @ m
            c = f[k - 1] @ c @ f[k - 1].T + params.q * qt[k - 1]
        pm[k], pc[k] = m, c
        if not np.isnan(y[k, 0]):
            s = c[:2, :2] + params.r
            det = s[0, 0] * s[1, 1] - s[0, 1] * s[1, 0]
            s_inv = np.array([[s[1, 1], -s[0, 1]], [-s[1, 0], s[0, 0]]]) / det  # 2x2: explicit inverse
            gain = c[:, :2] @ s_inv  # C H^T S^-1
            resid = y[k] - m[:2]
            m = m + gain @ resid
            ikh = EYE4 - gain @ H
            c = ikh @ c @ ikh.T + gain @ params.r @ gain.T  # Joseph form
            loglik += -0.5 * (resid @ s_inv @ resid + math.log(det) + 2 * math.log(2 * math.pi))
        m_all[k], c_all[k] = m, c
    return Filtered(pm, pc, m_all, c_all, loglik)


def rts_smoother(times: NDArray, filtered: Filtered) -> Smoothed:
    """Rauch-Tung-Striebel: E[x_k | all], Cov, and the lag-one Cov(x_k, x_{k-1} | all)."""
    n = len(times)
    f, _ = transition(np.diff(times))
    ms, cs = filtered.mean.copy(), filtered.cov.copy()
    cross = np.zeros((n, 4, 4))
    for k in range(n - 2, -1, -1):
        j = np.linalg.solve(filtered.pred_cov[k + 1], f[k] @ filtered.cov[k]).T  # C_k F^T Cpred^-1
        ms[k] = filtered.mean[k] + j @ (ms[k + 1] - filtered.pred_mean[k + 1])
        cs[k] = filtered.cov[k] + j @ (cs[k + 1] - filtered.pred_cov[k + 1]) @ j.T
        cross[k + 1] = cs[k + 1] @ j.T
    return Smoothed(ms, cs, cross)


def initial_params(times: NDArray, y: NDArray) -> CVParams:
    """A start for EM: R and q from the measurements' differences, a broad prior at the first."""
    seen = ~np.isnan(y[:, 0])
    t, z = times[seen], y[seen]
    dt = np.maximum(np.diff(t), 1e-9)
    v = np.diff(z, axis=0) / dt[:, None]
    spread = float(np.var(z - z.mean(axis=0)) + 1.0)
    r = max(float(np.var(np.diff(z, axis=0))) / 4, 1e-2) * np.eye(2)
    q = max(float(np.var(np.diff(v, axis=0))) / max(float(np.mean(dt)), 1e-9), 1e-4) if len(v) > 1 else 1.0
    v0 = v[0] if len(v) else np.zeros(2)
    p0 = np.diag([spread, spread, float(np.var(v)) + 1.0, float(np.var(v)) + 1.0]) if len(v) else np.eye(4) * spread
    return CVParams(q, r, np.concatenate([z[0], v0]), p0)


def em_cv(
    times: NDArray, y: NDArray, iterations: int = 100, tol: float = 1e-6, start: CVParams | None = None
) -> tuple[CVParams, list[float]]:
    """EM for q, R and x0 (module docstring); stops when the log-likelihood gains less than
    `tol` (relative). Returns the parameters and the log-likelihood of each iteration."""
    params = initial_params(times, y) if start is None else start
    seen = ~np.isnan(y[:, 0])
    dt = np.diff(times)
    f, _ = transition(dt)
    qinv = _qt_inverse(dt)
    history: list[float] = []
    for _ in range(iterations):
        filt = kalman_filter(times, y, params)
        history.append(filt.loglik)
        if len(history) > 1 and abs(history[-1] - history[-2]) <= tol * abs(history[-2]):
            break
        sm = rts_smoother(times, filt)
        exx = sm.cov + np.einsum("ni,nj->nij", sm.mean, sm.mean)
        if len(times) > 1:
            cross = sm.cross[1:] + np.einsum("ni,nj->nij", sm.mean[1:], sm.mean[:-1])  # E[x_k x_{k-1}^T]
            fc = np.einsum("nij,nkj->nik", f, cross)  # F E[x_{k-1} x_k^T]
            s = exx[1:] - fc - np.transpose(fc, (0, 2, 1)) + np.einsum("nij,njk,nlk->nil", f, exx[:-1], f)
            q = float(np.einsum("nij,nji->", qinv, s)) / (4 * (len(times) - 1))
        else:
            q = params.q
        resid = y[seen] - sm.mean[seen, :2]
        r = (np.einsum("ni,nj->ij", resid, resid) + sm.cov[seen, :2, :2].sum(axis=0)) / seen.sum()
        r = 0.5 * (r + r.T) + MIN_VARIANCE * np.eye(2)
        params = CVParams(max(q, MIN_VARIANCE), r, sm.mean[0].copy(), params.p0)
    return params, history


def cv_estimates(
    meas_times: NDArray, meas_xy: NDArray, eval_times: NDArray, iterations: int = 100
) -> tuple[NDArray, NDArray, CVParams]:
    """EM on the measurements, then the filtered and the smoothed positions (n_eval, 2) at
    `eval_times` (the filter predicts between measurements)."""
    params, _ = em_cv(meas_times, meas_xy, iterations)
    grid = np.union1d(meas_times, eval_times)
    y = np.full((len(grid), 2), np.nan)
    y[np.searchsorted(grid, meas_times)] = meas_xy
    filt = kalman_filter(grid, y, params)
    sm = rts_smoother(grid, filt)
    at = np.searchsorted(grid, eval_times)
    return filt.mean[at, :2], sm.mean[at, :2], params
