"""Approximate association sum and marginals by loopy belief propagation (Bethe approximation).

Paper section 2.2-2.3 and appendix A.1, in the scalar-message form of Williams & Lau (2010),
"Data association by loopy belief propagation". Each beacon's factors are divided by u_i,
    W_ij = w_ij / u_i,   log Z = sum_i log u_i + log Z',
so that "unmatched" weighs 1 for a beacon and "clutter" weighs 1 for a signal. Messages
(arrays (P, s, K)), started from nu = 1:
    mu_ij = W_ij / (1 + sum_{j' != j} W_ij' nu_ij')    (beacon i -> signal j)
    nu_ij = 1 / (1 + sum_{i' != i} mu_i'j)              (signal j -> beacon i)
iterated until no message of a particle changes by more than `tolerance` (relative), or
`max_iterations`. The leave-one-out sums are prefix + suffix cumulative sums, never
total - own (which cancels catastrophically when one term dominates). Beliefs:
    B_ij = W_ij nu_ij / (1 + sum_j' W_ij' nu_ij')       (= returned p_match)
and log Z' is estimated by -F(B), the monomer-dimer Bethe free energy
    F(B) = sum_ij [B_ij log(B_ij / W_ij) - (1 - B_ij) log(1 - B_ij)]
           + sum_i b_i log b_i + sum_j c_j log c_j,
    b_i = 1 - sum_j B_ij (beacon unmatched),  c_j = 1 - sum_i B_ij (signal is clutter).
On forest-shaped graphs (w_ij = 0, i.e. log w = -inf, off a forest) BP is exact; on
bipartite graphs in general the Bethe estimate never exceeds the exact log Z (Gurvits for
permanents, Lelarge 2017 for monomer-dimer models). Cost O(s K) per particle per iteration.
Messages are kept in linear scale, so log W_ij must stay below ~700 (float64 range).
"""

from __future__ import annotations

from functools import partial

import numpy as np
from numpy.typing import NDArray
from scipy.special import xlog1py, xlogy

from ..config import Config
from .base import Association, Engine


def associate(
    log_match: NDArray,
    log_unheard: NDArray,
    *,
    tolerance: float = 1e-9,
    max_iterations: int = 500,
    marginals: bool = True,
    log_echo: NDArray | None = None,
) -> Association:
    """Bethe estimate of log Z and BP pair marginals (see module docstring).

    `marginals` is accepted for the common engine interface; BP's marginals are its
    beliefs, which the Bethe estimate needs anyway, so they are always returned.
    `log_echo` is accepted and not used: the graph pairs each beacon with one signal, so
    to BP an echo (a source's second arrival) is clutter; the exact engine sums them.

    Particles whose messages have not converged after `max_iterations` get the beliefs of
    the last iteration.
    """
    log_match = np.asarray(log_match, dtype=np.float64)
    log_unheard = np.asarray(log_unheard, dtype=np.float64)
    n, s, k = log_match.shape
    log_u_total = log_unheard.sum(axis=1)
    if k == 0 or s == 0:
        return Association(log_u_total, np.zeros((n, s, k)))
    log_w = log_match - log_unheard[:, :, None]
    w = np.exp(log_w)
    _, nu, _ = message_passing(w, tolerance=tolerance, max_iterations=max_iterations)
    p_match = beliefs(w, nu)
    return Association(log_u_total + bethe_log_z(log_w, p_match), p_match)


def _leave_one_out_sum(x: NDArray, axis: int) -> NDArray:
    """sum_{m != k} x_m along `axis`, as (sum of x before k) + (sum of x after k).

    Terms are non-negative, so neither part cancels, unlike total - x_k.
    """
    x = np.moveaxis(x, axis, -1)
    before = np.zeros_like(x)
    np.cumsum(x[..., :-1], axis=-1, out=before[..., 1:])
    after = np.zeros_like(x)
    np.cumsum(x[..., :0:-1], axis=-1, out=after[..., -2::-1])
    return np.moveaxis(before + after, -1, axis)


def _relative_change(new: NDArray, old: NDArray) -> NDArray:
    """Per particle, max |new - old| / max(|new|, |old|) over messages (0 where both are 0)."""
    scale = np.maximum(np.abs(new), np.abs(old))
    diff = np.abs(new - old)
    rel = np.divide(diff, scale, out=np.zeros_like(diff), where=scale > 0)
    return rel.reshape(rel.shape[0], -1).max(axis=1)


def _update(w: NDArray, nu: NDArray) -> tuple[NDArray, NDArray]:
    """One sweep: beacon-to-signal messages mu from nu, then signal-to-beacon nu from mu."""
    mu = w / (1.0 + _leave_one_out_sum(w * nu, axis=2))
    nu = 1.0 / (1.0 + _leave_one_out_sum(mu, axis=1))
    return mu, nu


def message_passing(
    w: NDArray, *, tolerance: float = 1e-9, max_iterations: int = 500
) -> tuple[NDArray, NDArray, NDArray[np.intp]]:
    """Iterate the messages for normalised weights W (P, s, K) from nu = 1.

    Each particle stops once its largest relative message change is below `tolerance`.
    Returns (mu, nu, iterations), the last with the sweeps used per particle
    (`max_iterations` where a particle did not converge).
    """
    n = w.shape[0]
    mu_out = np.zeros_like(w)
    nu_out = np.ones_like(w)
    iterations = np.full(n, max_iterations, dtype=np.intp)
    active = np.arange(n)
    wa, mu, nu = w, mu_out.copy(), nu_out.copy()
    for it in range(1, max_iterations + 1):
        mu_new, nu_new = _update(wa, nu)
        change = np.maximum(_relative_change(mu_new, mu), _relative_change(nu_new, nu))
        mu, nu = mu_new, nu_new
        done = change < tolerance
        if it == max_iterations:
            done[:] = True
        if done.any():
            idx = active[done]
            mu_out[idx], nu_out[idx] = mu[done], nu[done]
            iterations[idx] = it
            keep = ~done
            active, wa, mu, nu = active[keep], wa[keep], mu[keep], nu[keep]
            if active.size == 0:
                break
    return mu_out, nu_out, iterations


def beliefs(w: NDArray, nu: NDArray) -> NDArray:
    """B_ij = W_ij nu_ij / (1 + sum_j' W_ij' nu_ij'): P(signal j from beacon i)."""
    a = w * nu
    return a / (1.0 + a.sum(axis=2, keepdims=True))


def bethe_free_energy(log_w: NDArray, b_match: NDArray) -> NDArray:
    """F(B) per particle for log weights log W (P, s, K) and beliefs B (module docstring)."""
    with np.errstate(invalid="ignore"):
        energy = np.where(b_match > 0, b_match * log_w, 0.0)  # 0 log 0 where W = 0
    edge = xlogy(b_match, b_match) - energy - xlog1py(1.0 - b_match, -b_match)
    unmatched = np.clip(1.0 - b_match.sum(axis=2), 0.0, None)  # b_i
    clutter = np.clip(1.0 - b_match.sum(axis=1), 0.0, None)  # c_j
    return edge.sum(axis=(1, 2)) + xlogy(unmatched, unmatched).sum(axis=1) + xlogy(clutter, clutter).sum(axis=1)


def bethe_log_z(log_w: NDArray, b_match: NDArray) -> NDArray:
    """Bethe estimate -F(B) of log Z' (normalised weights), per particle."""
    return -bethe_free_energy(log_w, b_match)


def from_config(config: Config) -> Engine:
    """BP with the configured stopping rule (`[bp]`)."""
    return partial(associate, tolerance=config.bp.tolerance, max_iterations=config.bp.max_iterations)
