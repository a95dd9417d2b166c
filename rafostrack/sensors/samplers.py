"""One tracking step of each algorithm of the paper: ABC-Rej, ABC-RW, ABC-PT and the
exact-likelihood MCMC, vectorised over B independent scenarios.

Each returns the step's velocity estimate v^_t (the mean of the retained states; the
position is x^_t = x^_{t-1} + v^_t) and its diagnostics.

- ABC-Rej (section 3.2): n draws from pi_0; keep those with rho < epsilon; estimate = their
  mean. When no draw is within epsilon, the draws at the smallest distance are kept (a
  nearest-neighbour fallback; the paper does not say; counted in `fallback`).
- ABC-RW (section 3.3): a Metropolis-Hastings chain of n iterations whose proposal is a
  fresh draw from pi_0 (the paper's "renewal process"); a proposal theta' is accepted if
  rho' < epsilon and u <= f(theta') pi_0(theta) / (f(theta) pi_0(theta')) (the paper's
  ratio with q = pi_0), so the chain targets f(theta) 1{rho < epsilon}. The chain starts at
  the first draw; until it first enters {rho < epsilon} any proposal inside is accepted
  (burn-in); estimate = the mean of the chain's states from then on.
- ABC-PT (section 4.1, Baragatti et al. 2013): C such chains with tolerances
  epsilon_1 < ... < epsilon_C; after each iteration's local moves, `swaps` times a pair of
  chains a < b drawn uniformly swaps states if the state of b is within epsilon_a (the f
  and pi_0 terms cancel between chains that differ only in their tolerance); estimate =
  the mean of chain 1 (tolerance epsilon_1).
- MCMC (section 5.1, "the MCMC random walk using the known likelihood"): a Gaussian
  random-walk Metropolis chain on theta targeting pi_0(theta) p(c_t | x_t, theta) (eq. 6,
  or the Poisson-binomial for Nt > 1, `sensors.log_likelihood`), started at the prior
  mean; estimate = the chain mean after `burn_in_fraction` of the iterations.

Every random number comes from the Generator passed in; all arithmetic on densities is in
log space.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .prior import StepPrior, distances, log_pseudo_likelihood
from .sensors import log_likelihood


@dataclass(frozen=True)
class StepResult:
    """One step's estimate and diagnostics for B scenarios."""

    v_hat: NDArray[np.float64]  # (B, Nt, 2)
    acceptance: NDArray[np.float64]  # (B,): accepted fraction (draws for Rej, moves for chains)
    fallback: NDArray[np.bool_]  # (B,): no state within the tolerance (nearest draws used)
    samples: NDArray[np.float64] | None = None  # (B, k, Nt, 2): the last k states kept (theta)
    swap_acceptance: NDArray[np.float64] | None = None  # (B,): ABC-PT's accepted swaps


def _nearest_mean(theta: NDArray, rho: NDArray) -> NDArray[np.float64]:
    """Mean of the draws at the smallest distance; theta (n, B, Nt, 2), rho (n, B)."""
    at_min = rho == rho.min(axis=0)
    return np.asarray((theta * at_min[..., None, None]).sum(axis=0) / at_min.sum(axis=0)[:, None, None])


def rejection_step(
    prior: StepPrior,
    counts: NDArray,
    sensors: NDArray,
    p_correct: float,
    *,
    draws: int,
    tolerance: float,
    rng: np.random.Generator,
    keep: int = 0,
) -> StepResult:
    """ABC-Rej (module docstring); the `keep` draws nearest the data (the accepted ones
    first) are returned for pictures."""
    theta = prior.sample(draws, 1, rng)[:, :, 0]  # (n, B, Nt, 2)
    rho = distances(theta[:, :, None], prior, counts, sensors, p_correct, rng)[:, :, 0]
    accepted = rho < tolerance
    n_acc = accepted.sum(axis=0)
    fallback = n_acc == 0
    mean_acc = (theta * accepted[..., None, None]).sum(axis=0) / np.maximum(n_acc, 1)[:, None, None]
    v_hat = np.where(fallback[:, None, None], _nearest_mean(theta, rho), mean_acc)
    samples = None
    if keep:
        order = np.argsort(rho, axis=0, kind="stable")[:keep]
        samples = np.moveaxis(np.take_along_axis(theta, order[..., None, None], axis=0), 0, 1)
    return StepResult(v_hat, n_acc / draws, fallback, samples)


def tolerance_ladder(tolerance: float, chains: int, ratio: float = np.sqrt(2.0)) -> NDArray[np.float64]:
    """ABC-PT's tolerances epsilon_c = tolerance * ratio^(c - 1), c = 1..C."""
    return np.asarray(tolerance * ratio ** np.arange(chains))


def abc_chain_step(
    prior: StepPrior,
    counts: NDArray,
    sensors: NDArray,
    p_correct: float,
    *,
    iterations: int,
    tolerances: NDArray,
    swaps: int,
    rng: np.random.Generator,
    f_scale: float = 1.0,
    keep: int = 0,
) -> StepResult:
    """ABC-RW (one tolerance, no swaps) or ABC-PT (a ladder, `swaps` per iteration); see
    the module docstring. Diagnostics are chain 1's; `keep` returns its last states (the
    nearest draws where it never entered its tolerance)."""
    eps = np.asarray(tolerances, dtype=float)
    n_chains = len(eps)
    theta = prior.sample(iterations, n_chains, rng)  # (n, B, C, Nt, 2)
    rho = distances(theta, prior, counts, sensors, p_correct, rng)  # (n, B, C)
    log_g = log_pseudo_likelihood(theta, prior.v_prev, prior.sd, f_scale) - prior.log_density(theta)
    log_u = np.log(rng.random(rho.shape))
    pairs = np.array([(a, b) for a in range(n_chains) for b in range(a + 1, n_chains)], dtype=np.intp)
    n_b = rho.shape[1]
    pick = rng.integers(0, max(len(pairs), 1), (iterations, swaps, n_b)) if swaps and len(pairs) else None
    chains = _Chains.start(theta[0], rho[0], log_g[0], eps)
    kept = np.empty((keep, *chains.theta[:, 0].shape)) if keep else None
    for k in range(1, iterations):
        chains.local_move(theta[k], rho[k], log_g[k], log_u[k], eps)
        if pick is not None:
            for s in range(swaps):
                chains.swap(pairs[pick[k, s], 0], pairs[pick[k, s], 1], eps)
        chains.accumulate()
        if kept is not None and k >= iterations - keep:
            kept[k - (iterations - keep)] = chains.theta[:, 0]
    fallback = chains.n_in[:, 0] == 0
    mean_in = chains.sums[:, 0] / np.maximum(chains.n_in[:, 0], 1)[:, None, None]
    v_hat = np.where(fallback[:, None, None], _nearest_mean(theta[:, :, 0], rho[:, :, 0]), mean_in)
    samples = None
    if kept is not None:
        samples = np.moveaxis(kept, 0, 1)
        for b in np.flatnonzero(fallback):  # a chain that never entered: show the nearest draws
            nearest = np.argsort(rho[:, b, 0], kind="stable")[:keep]
            samples[b] = theta[np.resize(nearest, keep), b, 0]
    swap_rate = chains.swap_ok / (swaps * (iterations - 1)) if pick is not None else None
    return StepResult(v_hat, chains.moves[:, 0] / (iterations - 1), fallback, samples, swap_rate)


@dataclass
class _Chains:
    """The C chains of B scenarios (`abc_chain_step`): current states theta (B, C, Nt, 2),
    their distances rho and log f / pi_0 terms g, whether each chain has entered its
    tolerance region, and the running counts (moves, swaps, sums of states inside)."""

    theta: NDArray[np.float64]
    rho: NDArray[np.float64]
    g: NDArray[np.float64]
    inside: NDArray[np.bool_]
    moves: NDArray[np.float64]
    swap_ok: NDArray[np.float64]
    sums: NDArray[np.float64]
    n_in: NDArray[np.float64]

    @classmethod
    def start(cls, theta: NDArray, rho: NDArray, log_g: NDArray, eps: NDArray) -> _Chains:
        """Chains at the first draws."""
        inside = rho < eps
        n_b, n_chains = rho.shape
        return cls(
            theta.copy(),
            rho.copy(),
            log_g.copy(),
            inside,
            np.zeros((n_b, n_chains)),
            np.zeros(n_b),
            np.where(inside[..., None, None], theta, 0.0),
            inside.astype(float),
        )

    def local_move(self, theta: NDArray, rho: NDArray, log_g: NDArray, log_u: NDArray, eps: NDArray) -> None:
        """Each chain's Metropolis-Hastings move to the iteration's proposal: accepted inside
        the tolerance if u <= g' / g, or at once while the chain has not yet entered."""
        ok = (rho < eps) & (~self.inside | (log_u < log_g - self.g))
        self.theta = np.where(ok[..., None, None], theta, self.theta)
        self.rho = np.where(ok, rho, self.rho)
        self.g = np.where(ok, log_g, self.g)
        self.moves += ok & self.inside  # moves of a chain already in its region
        self.inside |= ok

    def swap(self, a: NDArray[np.intp], b: NDArray[np.intp], eps: NDArray) -> None:
        """Per scenario, swap the states of chains a < b when b's state is within epsilon_a."""
        rows = np.arange(len(self.rho))
        go = self.rho[rows, b] < eps[a]
        self.swap_ok += go
        idx = rows[go]
        ia, ib = a[go], b[go]
        for arr in (self.theta, self.rho, self.g, self.inside):
            arr[idx, ia], arr[idx, ib] = arr[idx, ib].copy(), arr[idx, ia].copy()

    def accumulate(self) -> None:
        """Add the states of the chains inside their region to the running sums."""
        self.sums += np.where(self.inside[..., None, None], self.theta, 0.0)
        self.n_in += self.inside


def mcmc_step(
    prior: StepPrior,
    counts: NDArray,
    sensors: NDArray,
    p_correct: float,
    *,
    iterations: int,
    proposal_sd: float,
    rng: np.random.Generator,
    burn_in_fraction: float = 0.1,
    keep: int = 0,
) -> StepResult:
    """The exact-likelihood random-walk MCMC (module docstring); any number of targets."""
    b, nt, _ = prior.v_prev.shape
    steps = proposal_sd * rng.standard_normal((iterations, b, 1, nt, 2))
    log_u = np.log(rng.random((iterations, b)))

    def log_target(th: NDArray) -> NDArray:  # th (B, 1, Nt, 2) -> (B,)
        loglik = log_likelihood(counts, prior.positions(th)[:, 0], th[:, 0], sensors, p_correct)
        return np.asarray(prior.log_density(th)[:, 0] + loglik)

    cur = prior.v_prev[:, None].copy()
    cur_lp = log_target(cur)
    burn = int(burn_in_fraction * iterations)
    sums = np.zeros_like(cur[:, 0])
    accepted = np.zeros(b)
    kept = np.empty((keep, b, nt, 2)) if keep else None
    for k in range(iterations):
        prop = cur + steps[k]
        lp = log_target(prop)
        ok = log_u[k] < lp - cur_lp
        cur = np.where(ok[:, None, None, None], prop, cur)
        cur_lp = np.where(ok, lp, cur_lp)
        accepted += ok
        if k >= burn:
            sums += cur[:, 0]
        if kept is not None and k >= iterations - keep:
            kept[k - (iterations - keep)] = cur[:, 0]
    samples = None if kept is None else np.moveaxis(kept, 0, 1)
    return StepResult(sums / (iterations - burn), accepted / iterations, np.zeros(b, dtype=bool), samples)
