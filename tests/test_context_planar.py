"""The planar particle filter and the paper's point on a small case: the naive rule is
biased inside a wide region of CF 0.5, the cell-entry rule is not.

Oracle: the exact posterior on a 1-D lattice under the paper's world model (Fig. 3): the
region A (x >= 60) has one mobility m_A with P(m_A) = CF_A = 0.5, fixed in time, so a path
pays CF_A once, when it first enters A; computed by the forward recursion over (position,
A visited yet). The truth is drawn from the same world model (a random walk, paths that
enter A kept with probability 0.5). The rules' posteriors are computed exactly too (naive:
CF_A at every step in A; entry: CF_A at each move from B into A), and the planar filter is
checked against them.
"""

from __future__ import annotations

import numpy as np
import pytest

from rafostrack.context.grid import ContextGrid
from rafostrack.context.planar import Measurement, PlanarFilter, Sensor, polyline_truth, simulate_measurements

L, A_START, CF_A = 200, 60, 0.5
X = np.arange(L)
IN_A = X >= A_START
CF = np.where(IN_A, CF_A, 1.0)


def _kernel(q: float, drift: float) -> np.ndarray:
    d = X[None, :] - X[:, None] - drift
    k = np.exp(-0.5 * (d / q) ** 2) * (np.abs(d) <= 6 * q)
    return k / k.sum(axis=1, keepdims=True)  # k[i, j] = P(x' = j | x = i)


def _posterior_means(rule, k, y, observed, sigma, x0, prior_sd):
    """Exact posterior mean of x_t on the lattice under `rule` (module docstring)."""
    prior = np.exp(-0.5 * ((X - x0) / prior_sd) ** 2)
    if rule == "world":
        a = np.zeros((L, 2))
        a[~IN_A, 0], a[IN_A, 1] = prior[~IN_A], prior[IN_A] * CF_A
    else:
        a = prior * (CF if rule != "none" else 1.0)
    entry_kernel = k * np.where(IN_A[None, :] != IN_A[:, None], CF[None, :], 1.0)
    means = []
    for t in range(len(y)):
        if t > 0 and rule == "world":
            p0, p1 = a[:, 0] @ k, a[:, 1] @ k
            a = np.zeros_like(a)
            a[~IN_A, 0] = p0[~IN_A]
            a[IN_A, 1] = p0[IN_A] * CF_A + p1[IN_A]
            a[~IN_A, 1] = p1[~IN_A]
        elif t > 0:
            a = a @ (entry_kernel if rule == "entry" else k)
            a = a * (CF if rule == "naive" else 1.0)
        if t in observed:
            lik = np.exp(-0.5 * ((X - y[t]) / sigma) ** 2)
            a = a * (lik[:, None] if a.ndim == 2 else lik)
        a = a / a.sum()
        means.append((a.sum(axis=1) if a.ndim == 2 else a) @ X)
    return np.array(means)


def _world_truth(rng, k, steps, x0):
    """A path of the world model: a random walk; one entering A is kept with prob. CF_A."""
    while True:
        xs = [x0]
        for _ in range(1, steps):
            xs.append(int(rng.choice(L, p=k[xs[-1]])))
        if not IN_A[xs].any() or rng.random() < CF_A:
            return np.array(xs)


def test_naive_rule_is_biased_in_a_wide_cf_half_region_and_entry_is_not():
    k = _kernel(1.5, 0.3)  # drifting into A
    rng = np.random.default_rng(0)
    sigma, steps, x0 = 8.0, 100, 40
    observed = set(range(5, steps, 5))
    diff = {"naive": [], "entry": [], "none": []}
    for _ in range(16):
        xs = _world_truth(rng, k, steps, x0)
        y = xs + sigma * rng.standard_normal(steps)
        exact = _posterior_means("world", k, y, observed, sigma, x0, 2.0)
        inside = IN_A[xs]
        for rule in diff:
            m = _posterior_means(rule, k, y, observed, sigma, x0, 2.0)
            diff[rule].append((m - exact)[inside].mean() if inside.any() else 0.0)
    naive, entry = np.mean(diff["naive"]), np.mean(diff["entry"])
    # Naive: pulled out of A (towards B, lower x) by several lattice units; entry: within 0.3.
    assert naive < -3.0
    assert abs(entry) < 0.3
    assert abs(entry) < abs(naive) / 10


def _strip_grid() -> ContextGrid:
    """CF 1 for x < 59.5 (lattice cells < 60), 0.5 beyond, over a wide strip."""
    x_centres = np.arange(-50.5, 250.5, 1.0)
    cf = np.where(x_centres >= 59.5, CF_A, 1.0)[None, :].repeat(20, axis=0)
    return ContextGrid(-51.0, -10.0, 1.0, 1.0, cf, outside_cf=1.0)


@pytest.mark.parametrize("rule", ["naive", "entry"])
def test_planar_filter_matches_the_exact_lattice_posterior(rule):
    """The filter's posterior mean of x follows the exact lattice one under the same rule
    (random-walk motion, measurements at every 5th step), and so the naive rule's deviation
    from the world model is reproduced, the entry rule's absence of it too."""
    q, sigma, steps, x0 = 1.5, 6.0, 60, 56
    k = _kernel(q, 0.0)
    rng = np.random.default_rng(3)
    xs = _world_truth(rng, k, steps, x0)
    y = xs + sigma * rng.standard_normal(steps)
    meas = [Measurement(t, 0, np.array([y[t], 0.0])) for t in range(5, steps, 5)]
    lattice = _posterior_means(rule, k, y, {m.step for m in meas}, sigma, x0, 2.0)
    world = _posterior_means("world", k, y, {m.step for m in meas}, sigma, x0, 2.0)
    pf = PlanarFilter(_strip_grid(), rule, 4000, sigma, q, motion="rw")
    run = pf.run(steps - 1, meas, (float(x0), 0.0), 2.0, 0.0, np.random.default_rng(5))
    err = np.abs(run.estimate[:, 0] - lattice)
    assert err.mean() < 0.35
    if rule == "naive":
        assert np.abs(run.estimate[:, 0] - world).mean() > 1.0
    else:
        assert np.abs(run.estimate[:, 0] - world).mean() < 0.5


def test_context_keeps_the_cloud_out_of_a_cf_zero_region():
    """A CF-0 half plane: with the entry rule no particle weight ends up there; without
    context the cloud spills over."""
    cf = np.ones((80, 80))
    cf[:, 45:] = 0.0
    grid = ContextGrid(-20.0, -20.0, 1.0, 1.0, cf, outside_cf=1.0)  # CF 0 for 25 <= x < 60
    truth = polyline_truth([(5.0, 20.0), (24.0, 20.0), (24.0, 35.0)], 300)
    meas = simulate_measurements(truth, (Sensor(20.0, 20.0),), 30, 6.0, np.random.default_rng(1))
    out = {}
    for rule in ("none", "entry"):
        pf = PlanarFilter(None if rule == "none" else grid, rule, 500, 6.0, 0.01)
        run = pf.run(300, meas, (5.0, 20.0), 1.0, 0.05, np.random.default_rng(2), truth=truth, snapshot_steps=(299,))
        xy, w = run.snapshots[299]
        out[rule] = float(w[xy[:, 0] >= 25.0].sum())
    assert out["entry"] == 0.0
    assert out["none"] > 0.05


def test_filter_checks_its_arguments_and_is_reproducible():
    with pytest.raises(ValueError, match="needs a context grid"):
        PlanarFilter(None, "entry", 10, 1.0, 0.1)
    with pytest.raises(ValueError, match="rule must be"):
        PlanarFilter(None, "sometimes", 10, 1.0, 0.1)
    truth = polyline_truth([(0.0, 0.0), (10.0, 0.0)], 50)
    meas = simulate_measurements(truth, (Sensor(0.0, 0.0, 5.0),), 10, 1.0, np.random.default_rng(0))
    assert [m.step for m in meas] == [10, 20, 30, 40, 50][: len(meas)]
    assert all(np.hypot(*truth[m.step]) <= 5.0 for m in meas)
    runs = [PlanarFilter(None, "none", 50, 1.0, 0.01).run(50, meas, (0.0, 0.0), 1.0, 0.1, np.random.default_rng(9))
            for _ in range(2)]  # fmt: skip
    assert np.array_equal(runs[0].estimate, runs[1].estimate)
