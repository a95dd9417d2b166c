"""The smoother's compiled kernels against brute-force sums over every pair and component."""

import numpy as np
import pytest
from scipy.special import logsumexp

from rafostrack.smoothing.ffbsm_kernel import BLOCK, MIXTURE_TOL, backward_weights, log_mixture_density


def _mixture(rng: np.random.Generator, n_i: int, n_j: int, far: float):
    """A narrow kernel and a broad one of weight 1e-3 (a drift and its jump component), in
    whitened coordinates: za (2, I, 2), zb (2, J, 2); points j spread over `far` sds."""
    origins = rng.normal(0.0, 1.0, (n_i, 2))
    destinations = rng.normal(0.0, far, (n_j, 2))
    broad = 30.0  # the jump's sd in units of the drift's
    za = np.stack([origins, origins / broad])
    zb = np.stack([destinations, destinations / broad])
    log_norm = np.log([1 - 1e-3, 1e-3]) - np.log([1.0, broad**2]) - np.log(2 * np.pi)
    log_w = np.log(rng.dirichlet(np.ones(n_i)))
    return za, zb, log_norm, log_w


def _brute(za, zb, log_norm, log_w):
    """log f_c(x_j | x_i) + log W_i, every (c, i, j)."""
    q = ((zb[:, None, :, :] - za[:, :, None, :]) ** 2).sum(-1)  # (C, I, J)
    return log_norm[:, None, None] + log_w[None, :, None] - 0.5 * q


@pytest.mark.parametrize("far", [0.5, 3.0, 40.0])
def test_log_mixture_density_matches_the_full_sum(far):
    """Near the cloud the broad kernel may be left out (within MIXTURE_TOL of the density);
    far from it, where only the broad kernel reaches, it is summed exactly."""
    za, zb, log_norm, log_w = _mixture(np.random.default_rng(3), 60, 2 * BLOCK + 45, far)
    out = log_mixture_density(za, zb, log_norm, log_w)
    want = logsumexp(_brute(za, zb, log_norm, log_w), axis=(0, 1))
    assert np.all(np.abs(out - want) <= 1.01 * MIXTURE_TOL)
    narrow_only = logsumexp(_brute(za, zb, log_norm, log_w)[0], axis=0)
    needs_broad = want - narrow_only > 2 * MIXTURE_TOL
    np.testing.assert_allclose(out[needs_broad], want[needs_broad], rtol=0, atol=1e-9)
    if far == 40.0:
        assert needs_broad.sum() > 100  # the case was exercised


@pytest.mark.parametrize("far", [3.0, 40.0])
def test_backward_weights_match_the_ffbsm_sum(far):
    """S_i = W_i sum_j V_j f(x_j | x_i) / sum_k W_k f(x_j | x_k), within MIXTURE_TOL; far
    points reach the cloud only through the broad kernel."""
    rng = np.random.default_rng(4)
    za, zb, log_norm, log_w = _mixture(rng, 50, 2 * BLOCK + 45, far)
    v = rng.dirichlet(np.ones(zb.shape[1]))
    out = backward_weights(za, zb, log_norm, log_w, v)
    terms = logsumexp(_brute(za, zb, log_norm, log_w), axis=0)  # (I, J): over components
    pred = logsumexp(terms, axis=0)  # (J,)
    want = np.exp(logsumexp(terms - pred[None, :] + np.log(v)[None, :], axis=1))
    np.testing.assert_allclose(out, want, rtol=2 * MIXTURE_TOL)
    np.testing.assert_allclose(out.sum(), 1.0, rtol=1e-9)
