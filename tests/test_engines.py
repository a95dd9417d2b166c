"""Every association engine against one brute-force oracle.

The oracle enumerates every assignment of each signal to {clutter} U beacons that uses
each beacon at most once and sums the products of the factors directly in float64.
"""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest
from numpy.typing import NDArray

from rafostrack.config import load_config
from rafostrack.engines import ENGINES as REGISTERED
from rafostrack.engines import Association, Engine, SimulatingEngine, bp, exact
from rafostrack.errors import InputError
from rafostrack.model.measurement import association_factors

# Every registered engine that sums the factors, built from the default configuration (the
# registry is the list). Simulating engines (`abc`) take the window, not the factors, and
# estimate the likelihood by Monte Carlo: tests/test_abc_engine.py tests them against the
# exact likelihood (this oracle, through the exact engine) with statistical tolerances.
BUILT = {name: factory(load_config()) for name, factory in REGISTERED.items()}
ENGINES: dict[str, Engine] = {name: e for name, e in BUILT.items() if not isinstance(e, SimulatingEngine)}
# Marginal tolerance against the oracle on tree-shaped graphs (where BP is exact too).
MARGINAL_TOL = {"exact": 1e-9, "bp": 1e-6}


def oracle(log_match: NDArray, log_unheard: NDArray, log_echo: NDArray | None = None) -> tuple[NDArray, NDArray]:
    """(log Z, pair marginals) by enumerating every role of every signal, per particle:
    clutter, beacon i's first arrival, or (with `log_echo`) beacon i's echo, an echo
    needing the same beacon's first arrival at an earlier signal; each beacon has at most
    one of each."""
    n, s, k = log_match.shape
    w = np.exp(log_match)
    u = np.exp(log_unheard)
    echo = np.zeros((k, k)) if log_echo is None else np.exp(log_echo)
    # Role of signal j: 0 = clutter, 1 + i = beacon i's first arrival, 1 + s + i = its echo.
    terms, owners = [], []
    for roles in itertools.product(range(1 + (2 if log_echo is not None else 1) * s), repeat=k):
        first = {r - 1: j for j, r in enumerate(roles) if 1 <= r <= s}
        echoes = [(r - 1 - s, j) for j, r in enumerate(roles) if r > s]
        if sum(1 <= r <= s for r in roles) != len(first) or len({i for i, _ in echoes}) != len(echoes):
            continue
        if any(i not in first or first[i] >= j for i, j in echoes):
            continue
        term = np.ones(n)
        for i, j in first.items():
            term = term * w[:, i, j]
        for i, j in echoes:
            term = term * echo[first[i], j]
        for i in range(s):
            if i not in first:
                term = term * u[:, i]
        terms.append(term)
        owners.append([(r - 1) % s if r else -1 for r in roles])
    t = np.array(terms)  # (M, n)
    z = t.sum(axis=0)
    owner = np.array(owners, dtype=np.intp).reshape(len(owners), k)
    p_match = np.zeros((n, s, k))
    for i in range(s):
        for j in range(k):
            p_match[:, i, j] = t[owner[:, j] == i].sum(axis=0) / z
    return np.log(z), p_match


def random_forest_mask(rng: np.random.Generator, s: int, k: int) -> NDArray[np.bool_]:
    """A random forest on the bipartite graph beacons x signals, as an (s, K) edge mask."""
    parent = list(range(s + k))

    def root(v: int) -> int:
        while parent[v] != v:
            parent[v] = parent[parent[v]]
            v = parent[v]
        return v

    mask = np.zeros((s, k), dtype=bool)
    for e in rng.permutation(s * k):
        i, j = divmod(int(e), k)
        a, b = root(i), root(s + j)
        if a != b and rng.random() < 0.8:
            parent[a] = b
            mask[i, j] = True
    return mask


def tree_case(seed: int) -> tuple[NDArray, NDArray]:
    """Factors that vanish off a random forest; every third case has log w in [-30, 30]
    (one dominant term in a leave-one-out sum then hides the others if computed as
    total - own)."""
    rng = np.random.default_rng(seed)
    n, s, k = 3, int(rng.integers(1, 7)), int(rng.integers(1, 6))
    spread = 30.0 if seed % 3 == 0 else 8.0
    log_match = np.full((n, s, k), -np.inf)
    for p in range(n):
        mask = random_forest_mask(rng, s, k)
        log_match[p][mask] = rng.uniform(-spread, spread, mask.sum())
    return log_match, rng.uniform(-3, 1, (n, s))


def dense_case(seed: int, *, n: int = 4) -> tuple[NDArray, NDArray]:
    """Random dense factors; every fifth case has extreme weights (log w in [-30, 30])."""
    rng = np.random.default_rng(seed)
    s, k = int(rng.integers(1, 8)), int(rng.integers(0, 5))
    spread = 30.0 if seed % 5 == 0 else 5.0
    log_match = rng.uniform(-spread, spread, (n, s, k))
    log_unheard = rng.uniform(-spread / 2, min(spread / 2, 3.0), (n, s))
    return log_match, log_unheard


def assert_matches_oracle(
    result: Association, log_match: NDArray, log_unheard: NDArray, tol: float, log_echo: NDArray | None = None
) -> None:
    log_z, p_match = oracle(log_match, log_unheard, log_echo)
    np.testing.assert_allclose(result.log_z, log_z, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(result.p_match, p_match, rtol=0, atol=tol)


@pytest.mark.parametrize("engine", sorted(ENGINES))
@pytest.mark.parametrize("seed", range(40))
def test_tree_cases_match_oracle(engine: str, seed: int) -> None:
    log_match, log_unheard = tree_case(seed)
    result = ENGINES[engine](log_match, log_unheard)
    assert np.isfinite(result.log_z).all() and np.isfinite(result.p_match).all()
    assert_matches_oracle(result, log_match, log_unheard, MARGINAL_TOL[engine])


@pytest.mark.parametrize("engine", sorted(ENGINES))
@pytest.mark.parametrize("shape", [(2, 0, 3), (2, 3, 0), (2, 0, 0)])
def test_empty_windows(engine: str, shape: tuple[int, int, int]) -> None:
    n, s, _ = shape
    log_unheard = np.linspace(-1, 0, n * s).reshape(n, s)
    result = ENGINES[engine](np.zeros(shape), log_unheard)
    np.testing.assert_allclose(result.log_z, log_unheard.sum(axis=1))
    assert result.p_match.shape == shape


@pytest.mark.parametrize("seed", range(60))
def test_exact_dense_cases_match_oracle(seed: int) -> None:
    log_match, log_unheard = dense_case(seed)
    assert_matches_oracle(exact.associate(log_match, log_unheard), log_match, log_unheard, 1e-9)


@pytest.mark.parametrize("shape", [(3, 1, 1), (3, 1, 4), (3, 7, 1), (3, 7, 4), (3, 4, 0)])
def test_exact_corner_shapes_match_oracle(shape: tuple[int, int, int]) -> None:
    rng = np.random.default_rng(sum(shape))
    log_match = rng.uniform(-30, 30, shape)
    log_unheard = rng.uniform(-10, 3, shape[:2])
    assert_matches_oracle(exact.associate(log_match, log_unheard), log_match, log_unheard, 1e-9)


def echo_case(seed: int) -> tuple[NDArray, NDArray, NDArray]:
    """Dense factors with echo pair terms (upper triangle finite; some pairs impossible)."""
    log_match, log_unheard = dense_case(seed)
    rng = np.random.default_rng(10_000 + seed)
    k = log_match.shape[2]
    log_echo = np.where(np.triu(np.ones((k, k), dtype=bool), 1), rng.uniform(-6.0, 4.0, (k, k)), -np.inf)
    log_echo[rng.random((k, k)) < 0.2] = -np.inf
    return log_match, log_unheard, log_echo


@pytest.mark.parametrize("seed", range(30))
def test_exact_with_echoes_matches_oracle(seed: int) -> None:
    log_match, log_unheard, log_echo = echo_case(seed)
    result = exact.associate(log_match, log_unheard, log_echo=log_echo)
    assert_matches_oracle(result, log_match, log_unheard, 1e-9, log_echo)


@pytest.mark.parametrize("seed", range(10))
def test_exact_with_echoes_per_particle_matches_oracle(seed: int) -> None:
    """One echo table per particle (a batch of windows, `calibrate.association`): each
    particle's sum and marginals are those of its own table, some pairs of some tables
    being absent (-inf) while other tables have them."""
    rng = np.random.default_rng(1000 + seed)
    n, s, k = 3, int(rng.integers(1, 5)), int(rng.integers(2, 5))
    log_match = rng.uniform(-4.0, 4.0, (n, s, k))
    log_unheard = rng.uniform(-2.0, 1.0, (n, s))
    later = np.triu(np.ones((k, k), dtype=bool), 1)
    log_echo = np.where(later, rng.uniform(-6.0, 4.0, (n, k, k)), -np.inf)
    log_echo[rng.random((n, k, k)) < 0.3] = -np.inf
    result = exact.associate(log_match, log_unheard, log_echo=log_echo)
    for p in range(n):
        log_z, p_match = oracle(log_match[p : p + 1], log_unheard[p : p + 1], log_echo[p])
        np.testing.assert_allclose(result.log_z[p], log_z[0], rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(result.p_match[p], p_match[0], rtol=0, atol=1e-9)


def test_echo_factors_of_a_realistic_window_match_oracle() -> None:
    """The model's echo terms (`model.measurement.echo_factors`) through the exact engine: two arrivals
    20 s apart near one beacon's prediction are both that beacon's, not one and clutter
    (the echo : clutter odds are e g(20.5 s) / Lambda = 0.05 * exp(-1.025) / 20 * 4200 ~ 3.8)."""
    model = dataclasses.replace(load_config().model, echo_fraction=0.05, multipath_delay_s=20.0)
    mu = np.array([[1000.0, 2500.0, 3100.0]])
    toa = np.array([1000.5, 1021.0, 2499.0])
    f = association_factors(mu, np.full(mu.shape, 0.9), toa, max_signals=4, window_s=model.window_s, model=model)
    result = exact.associate(f.log_match, f.log_unheard, log_echo=f.log_echo)
    assert_matches_oracle(result, f.log_match, f.log_unheard, 1e-9, f.log_echo)
    assert result.p_match[0, 0, 0] > 0.99 and result.p_match[0, 0, 1] == pytest.approx(3.77 / 4.77, abs=0.02)
    without = exact.associate(f.log_match, f.log_unheard)
    assert without.p_match[0, 0, 1] < 0.01  # no echoes: the second arrival is clutter


def test_bp_bethe_bound_and_valid_marginals() -> None:
    """On loopy graphs the Bethe log Z never exceeds the exact one; beliefs stay valid."""
    for seed in range(300):
        log_match, log_unheard = dense_case(1000 + seed)
        approx = bp.associate(log_match, log_unheard)
        truth = exact.associate(log_match, log_unheard)
        assert np.all(approx.log_z <= truth.log_z + 1e-9), seed
        p = approx.p_match
        assert np.isfinite(p).all() and np.all((p >= 0.0) & (p <= 1.0)), seed
        assert np.all(p.sum(axis=2) <= 1.0 + 1e-12), seed
        assert np.all(p.sum(axis=1) <= 1.0 + 1e-6), seed


def test_bp_leave_one_out_sum_does_not_cancel() -> None:
    x = np.array([[[1e20, 1.0, 2.0], [3.0, 1e-30, 0.0]]])
    np.testing.assert_array_equal(
        bp._leave_one_out_sum(x, axis=2), [[[3.0, 1e20 + 2.0, 1e20 + 1.0], [1e-30, 3.0, 3.0]]]
    )
    np.testing.assert_array_equal(bp._leave_one_out_sum(x, axis=1), [[[3.0, 1e-30, 0.0], [1e20, 1.0, 2.0]]])


def test_exact_refuses_many_signals() -> None:
    with pytest.raises(InputError, match="--engine bp"):
        exact.associate(np.zeros((1, 2, 13)), np.zeros((1, 2)))


def realistic_factors() -> tuple[NDArray, NDArray]:
    model = load_config().model
    rng = np.random.default_rng(7)
    base = rng.uniform(300.0, 3900.0, 6)
    mu = base + rng.normal(0.0, 5.0, (5, 6))  # 5 particles, 6 beacons
    toa = np.sort(np.r_[base[[0, 2, 3]] + rng.normal(0.0, 2.0, 3), rng.uniform(0, model.window_s)])
    f = association_factors(
        mu,
        np.full(mu.shape, model.p_detect),
        toa,
        max_signals=model.max_signals,
        window_s=model.window_s,
        model=model,
    )
    return f.log_match, f.log_unheard


def test_exact_realistic_case_matches_oracle() -> None:
    log_match, log_unheard = realistic_factors()
    assert_matches_oracle(exact.associate(log_match, log_unheard), log_match, log_unheard, 1e-9)


def test_bp_realistic_case_is_close() -> None:
    log_match, log_unheard = realistic_factors()
    approx = bp.associate(log_match, log_unheard)
    truth = exact.associate(log_match, log_unheard)
    assert np.all(approx.log_z <= truth.log_z + 1e-9)
    np.testing.assert_allclose(approx.log_z, truth.log_z, atol=0.1)
    np.testing.assert_allclose(approx.p_match, truth.p_match, atol=0.05)
