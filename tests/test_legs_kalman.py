"""The Kalman baseline against the joint Gaussian (brute force), and EM on a known model."""

from __future__ import annotations

import numpy as np
import pytest

from rafostrack.legs.kalman import CVParams, H, cv_estimates, em_cv, kalman_filter, rts_smoother, transition


def _joint(times, params):
    """Mean (4n,) and covariance (4n, 4n) of all states, by the recursion."""
    n = len(times)
    f, qt = transition(np.diff(times))
    mean = [params.x0]
    cov = np.zeros((4 * n, 4 * n))
    cov[:4, :4] = params.p0
    for k in range(1, n):
        mean.append(f[k - 1] @ mean[-1])
        prev = cov[4 * (k - 1) : 4 * k, : 4 * k]  # Cov(x_{k-1}, x_0..k-1)
        cov[4 * k : 4 * k + 4, : 4 * k] = f[k - 1] @ prev
        cov[: 4 * k, 4 * k : 4 * k + 4] = cov[4 * k : 4 * k + 4, : 4 * k].T
        cov[4 * k : 4 * k + 4, 4 * k : 4 * k + 4] = (
            f[k - 1] @ prev[:, 4 * (k - 1) :] @ f[k - 1].T + params.q * qt[k - 1]
        )
    return np.concatenate(mean), cov


def _condition(times, y, params, upto):
    mean, cov = _joint(times, params)
    rows = [k for k in range(upto + 1) if not np.isnan(y[k, 0])]
    big_h = np.zeros((2 * len(rows), 4 * len(times)))
    for i, k in enumerate(rows):
        big_h[2 * i : 2 * i + 2, 4 * k : 4 * k + 4] = H
    r = np.kron(np.eye(len(rows)), params.r)
    s = big_h @ cov @ big_h.T + r
    gain = cov @ big_h.T @ np.linalg.inv(s)
    resid = np.concatenate([y[k] for k in rows]) - big_h @ mean
    post_mean = mean + gain @ resid
    post_cov = cov - gain @ big_h @ cov
    loglik = -0.5 * (resid @ np.linalg.solve(s, resid) + np.linalg.slogdet(s)[1] + len(resid) * np.log(2 * np.pi))
    return post_mean.reshape(-1, 4), post_cov, loglik


def test_filter_and_smoother_equal_the_joint_gaussian():
    times = np.array([0.0, 0.7, 2.0, 2.5, 4.0, 6.5])
    y = np.array([[0.0, 1.0], [np.nan, np.nan], [2.0, 0.5], [3.1, 0.2], [np.nan, np.nan], [6.0, -1.0]])
    params = CVParams(0.4, np.array([[0.5, 0.1], [0.1, 0.3]]), np.array([0.1, 0.9, 1.0, 0.0]), np.diag([2.0, 2, 1, 1]))
    filt = kalman_filter(times, y, params)
    sm = rts_smoother(times, filt)
    full_mean, full_cov, loglik = _condition(times, y, params, len(times) - 1)
    np.testing.assert_allclose(sm.mean, full_mean, atol=1e-9)
    for k in range(len(times)):
        np.testing.assert_allclose(sm.cov[k], full_cov[4 * k : 4 * k + 4, 4 * k : 4 * k + 4], atol=1e-9)
        np.testing.assert_allclose(filt.mean[k], _condition(times, y, params, k)[0][k], atol=1e-9)
    np.testing.assert_allclose(sm.cross[3], full_cov[12:16, 8:12], atol=1e-9)
    assert filt.loglik == pytest.approx(loglik)


def test_em_increases_the_likelihood_and_recovers_the_noise_levels():
    rng = np.random.default_rng(3)
    n = 400
    times = np.cumsum(rng.uniform(0.5, 2.0, n))
    f, qt = transition(np.diff(times))
    q_true, r_true = 0.3, np.diag([4.0, 1.0])
    x = np.zeros((n, 4))
    x[0] = [0, 0, 1, -1]
    for k in range(1, n):
        x[k] = f[k - 1] @ x[k - 1] + rng.multivariate_normal(np.zeros(4), q_true * qt[k - 1])
    y = x[:, :2] + rng.multivariate_normal(np.zeros(2), r_true, n)
    params, history = em_cv(times, y, iterations=80, tol=0.0)
    assert np.all(np.diff(history) > -1e-6)
    assert params.q == pytest.approx(q_true, rel=0.3)
    np.testing.assert_allclose(np.diag(params.r), np.diag(r_true), rtol=0.3)
    assert abs(params.r[0, 1]) < 0.3


def test_estimates_at_times_between_measurements():
    t = np.arange(0.0, 50.0, 5.0)
    xy = np.column_stack([2 * t, -t]) + np.random.default_rng(0).normal(0, 0.5, (len(t), 2))
    filt, smooth, _ = cv_estimates(t, xy, np.arange(1.0, 46.0))
    truth = np.column_stack([2 * np.arange(1.0, 46.0), -np.arange(1.0, 46.0)])
    assert np.abs(smooth - truth).max() < 2.0 and np.abs(filt - truth).max() < 4.0
