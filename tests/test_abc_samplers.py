"""ABC-Rej, ABC-RW, ABC-PT and the exact MCMC against brute-force grid posteriors on a tiny
case: one target, nine sensors, one step (rafostrack.sensors.samplers).

The oracle evaluates on a fine grid of theta = v_t:
- the exact posterior pi_0(theta) p(c | theta) (eq. 6);
- the ABC posterior of tolerance epsilon, pi_0(theta) P(rho(c~(theta), c) < epsilon): for
  one target rho is the number of sensors whose simulated bit differs from the observed
  one, a sum of independent Bernoullis (Poisson-binomial, by convolution);
- the target of the ABC chains, f(theta) P(rho < epsilon).
For epsilon <= 1, rho < epsilon means c~ = c, so the ABC posterior IS the exact one.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from numpy.typing import NDArray

from rafostrack.sensors.prior import StepPrior, log_pseudo_likelihood
from rafostrack.sensors.samplers import abc_chain_step, mcmc_step, rejection_step, tolerance_ladder
from rafostrack.sensors.sensors import approaching, log_likelihood, sensor_grid, simulate_counts

PE = 0.85
SD = 0.5
SENSORS = sensor_grid(9, 10.0)
X_PREV = np.array([[2.0, -1.0]])
V_PREV = np.array([[1.0, 0.5]])


def observed_counts() -> NDArray:
    rng = np.random.default_rng(11)
    theta = V_PREV + np.array([[0.3, -0.4]])
    return simulate_counts(X_PREV + theta, theta, SENSORS, PE, rng)[None]  # (B = 1, Ns)


COUNTS = observed_counts()
HALF = 5 * SD
TICKS = np.linspace(-HALF, HALF, 301)
GRID = V_PREV[0] + np.stack(np.meshgrid(TICKS, TICKS, indexing="ij"), axis=-1).reshape(-1, 1, 2)  # (G, 1, 2)


def log_prior_grid() -> NDArray:
    return -0.5 * (((GRID - V_PREV) / SD) ** 2).sum(axis=(1, 2))


A_GRID = approaching(X_PREV + GRID, GRID, SENSORS)[..., 0]  # (G, Ns)


def p_within(eps: float) -> NDArray:
    """P(rho < eps | theta) on the grid (Poisson-binomial over sensors)."""
    mismatch = np.where(COUNTS == A_GRID, 1 - PE, PE)
    pmf = np.zeros((len(GRID), len(SENSORS) + 1))
    pmf[:, 0] = 1.0
    for i in range(len(SENSORS)):
        pmf[:, 1:] = pmf[:, 1:] * (1 - mismatch[:, i, None]) + pmf[:, :-1] * mismatch[:, i, None]
        pmf[:, 0] *= 1 - mismatch[:, i]
    return pmf[:, np.arange(len(SENSORS) + 1) < eps].sum(axis=1)


def normalise(log_w: NDArray) -> NDArray:
    w = np.exp(log_w - log_w.max())
    return w / w.sum()


def exact_posterior() -> NDArray:
    return normalise(log_prior_grid() + log_likelihood(COUNTS, X_PREV + GRID, GRID, SENSORS, PE))


def abc_posterior(eps: float) -> NDArray:
    with np.errstate(divide="ignore"):
        return normalise(log_prior_grid() + np.log(p_within(eps)))


def chain_target(eps: float) -> NDArray:
    log_f = log_pseudo_likelihood(GRID[:, None, None], V_PREV[None], SD)[:, 0, 0]
    with np.errstate(divide="ignore"):
        return normalise(log_f + np.log(p_within(eps)))


def mean_sd(w: NDArray) -> tuple[NDArray, NDArray]:
    m = (w[:, None] * GRID[:, 0]).sum(axis=0)
    return m, np.sqrt((w[:, None] * (GRID[:, 0] - m) ** 2).sum(axis=0))


def replicated_prior(b: int) -> tuple[StepPrior, NDArray]:
    return StepPrior(np.repeat(X_PREV[None], b, 0), np.repeat(V_PREV[None], b, 0), SD), np.repeat(COUNTS, b, 0)


def test_abc_posterior_is_exact_for_eps_up_to_one_and_drifts_away_as_eps_grows():
    exact = exact_posterior()
    np.testing.assert_allclose(abc_posterior(1.0), exact, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(abc_posterior(0.5), exact, rtol=1e-9, atol=1e-15)
    tv = [0.5 * np.abs(abc_posterior(eps) - exact).sum() for eps in (1.0, 2.0, 3.0, 5.0, 10.0)]
    assert tv[0] < 1e-12
    assert all(b > a + 0.01 for a, b in itertools.pairwise(tv)), tv  # grows with eps
    assert tv[-1] > 0.3  # eps > Ns: the prior


def test_exact_mcmc_matches_the_grid_posterior():
    b = 300
    prior, counts = replicated_prior(b)
    result = mcmc_step(
        prior, counts, SENSORS, PE, iterations=600, proposal_sd=0.4, rng=np.random.default_rng(1), keep=400
    )
    mean, sd = mean_sd(exact_posterior())
    est = result.v_hat[:, 0]
    se = est.std(axis=0, ddof=1) / np.sqrt(b)
    assert np.all(np.abs(est.mean(axis=0) - mean) < 4 * se + 2e-3), (est.mean(axis=0), mean, se)
    samples = result.samples[:, :, 0].reshape(-1, 2)
    np.testing.assert_allclose(samples.std(axis=0), sd, rtol=0.06)
    assert 0.15 < result.acceptance.mean() < 0.6
    assert not result.fallback.any()


@pytest.mark.parametrize("eps", [1.0, 3.0, 6.0])
def test_abc_rejection_samples_its_abc_posterior(eps):
    prior, counts = replicated_prior(1)
    draws = 60_000
    result = rejection_step(
        prior, counts, SENSORS, PE, draws=draws, tolerance=eps, rng=np.random.default_rng(2), keep=draws
    )
    mean, sd = mean_sd(abc_posterior(eps))
    n_acc = result.acceptance[0] * draws
    assert n_acc > 500
    assert np.all(np.abs(result.v_hat[0, 0] - mean) < 4 * sd / np.sqrt(n_acc)), (result.v_hat[0, 0], mean)
    # the acceptance rate is the prior probability of rho < eps
    p_acc = float((normalise(log_prior_grid()) * p_within(eps)).sum())
    assert result.acceptance[0] == pytest.approx(p_acc, abs=4 * np.sqrt(p_acc / draws))


def test_abc_rejection_approaches_the_exact_posterior_as_eps_shrinks():
    exact_mean, exact_sd = mean_sd(exact_posterior())
    errors = []
    for eps in (8.0, 4.0, 2.0, 1.0):
        prior, counts = replicated_prior(1)
        result = rejection_step(prior, counts, SENSORS, PE, draws=60_000, tolerance=eps, rng=np.random.default_rng(3))
        errors.append(float(np.linalg.norm(result.v_hat[0, 0] - exact_mean)))
    assert errors == sorted(errors, reverse=True), errors
    n_acc_floor = 500
    assert errors[-1] < 4 * exact_sd.max() / np.sqrt(n_acc_floor)


def test_rejection_falls_back_to_the_nearest_draws():
    prior, counts = replicated_prior(2)
    result = rejection_step(prior, counts, SENSORS, PE, draws=20, tolerance=0.0, rng=np.random.default_rng(4))
    assert result.fallback.all() and (result.acceptance == 0).all()
    assert np.isfinite(result.v_hat).all()


@pytest.mark.parametrize("chains", [1, 4])
def test_abc_chains_target_f_times_the_abc_indicator(chains):
    """ABC-RW (one chain) and ABC-PT (a ladder with swaps): chain 1's states follow
    f(theta) P(rho < eps_1 | theta)."""
    b, eps = 200, 2.0
    prior, counts = replicated_prior(b)
    ladder = tolerance_ladder(eps, chains)
    result = abc_chain_step(
        prior, counts, SENSORS, PE, iterations=500, tolerances=ladder, swaps=chains if chains > 1 else 0,
        rng=np.random.default_rng(5 + chains), keep=300,
    )  # fmt: skip
    mean, sd = mean_sd(chain_target(eps))
    samples = result.samples[:, :, 0]  # (B, keep, 2)
    est = samples.mean(axis=1)
    se = est.std(axis=0, ddof=1) / np.sqrt(b)
    assert np.all(np.abs(est.mean(axis=0) - mean) < 4 * se + 2e-3), (est.mean(axis=0), mean, se)
    np.testing.assert_allclose(samples.reshape(-1, 2).std(axis=0), sd, rtol=0.08)
    assert not result.fallback.any()
    if chains > 1:
        assert result.swap_acceptance is not None and 0.05 < result.swap_acceptance.mean() < 1


def test_tolerance_ladder():
    np.testing.assert_allclose(tolerance_ladder(2.0, 3, 2.0), [2.0, 4.0, 8.0])
