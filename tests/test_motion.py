"""Motion models (`rafostrack.motion`): every registered model against the same checks.

- its k-day transition is the exact one: it equals k one-day transitions composed
  (Chapman-Kolmogorov), and matches a fine-step Euler-Maruyama simulation of the model's
  stochastic differential equation (written out here, independently of the model's code);
- `propagate` draws from that transition (sample moments within Monte Carlo margins);
- `initial` scatters positions about the fix and velocities from the stationary law.
"""

from __future__ import annotations

import numpy as np
import pytest

from rafostrack.config import load_config, with_overrides
from rafostrack.domain import Particles
from rafostrack.model.geodesy import local_offsets_km
from rafostrack.motion import (
    MOTION_MODELS,
    ClockWalk,
    IntegratedOU,
    JumpMixture,
    MotionModel,
    RandomWalk,
    motion_from_config,
)

LAT0, LON0 = -57.0, -95.0

# One model of each kind, at settings away from the defaults.
CASES: dict[str, MotionModel] = {
    "random_walk": RandomWalk(4.0, mean_current_km_per_day=(2.5, -1.0)),
    "ou": IntegratedOU(velocity_sd_km_per_day=5.0, decorrelation_days=3.0, mean_current_km_per_day=(4.0, 1.5)),
}


def test_every_registered_model_has_a_case_and_builds_from_config():
    assert set(CASES) == set(MOTION_MODELS)
    for name in MOTION_MODELS:
        model = motion_from_config(with_overrides(load_config(), motion={"model": name}).motion)
        assert model.name == name and model.dim == (4 if model.has_velocity else 2)


def _euler_maruyama(model: MotionModel, x0: np.ndarray, days: float, rng: np.random.Generator, n: int) -> np.ndarray:
    """n paths of the model's SDE from x0 by Euler-Maruyama with 1/200-day steps: the
    oracle, written from the models' stated SDEs, not from their transition code."""
    h = 1.0 / 200.0
    x = np.repeat(x0[:, None], n, axis=1).astype(float)
    vbar = np.asarray(model.mean_current_km_per_day, dtype=float)[:, None]
    for _ in range(round(days / h)):
        dw = rng.standard_normal((2, n)) * np.sqrt(h)
        if isinstance(model, RandomWalk):  # dx = vbar dt + D dW
            x = x + vbar * h + model.diffusion_km_per_day * dw
        else:  # du = -u / T dt + sigma sqrt(2 / T) dW, dx = (vbar + u) dt
            t, sd = model.decorrelation_days, model.velocity_sd_km_per_day
            pos, vel = x[:2], x[2:]
            x = np.concatenate([pos + vel * h, vel - (vel - vbar) / t * h + sd * np.sqrt(2.0 / t) * dw])
    return x


@pytest.mark.parametrize("name", sorted(CASES))
@pytest.mark.parametrize("days", [0.5, 6.0])
def test_exact_transition_matches_a_monte_carlo_of_the_sde(name, days):
    """Mean and covariance of the k-day transition against 20,000 fine-step SDE paths
    (margins: 4 Monte Carlo standard errors of each moment, plus the Euler bias)."""
    model = CASES[name]
    x0 = np.zeros(model.dim)
    if model.has_velocity:
        x0[2:] = (-3.0, 6.0)  # away from the mean current, so relaxation shows
    n = 20_000
    paths = _euler_maruyama(model, x0, days, np.random.default_rng(3), n)
    tr = model.transition(days)
    mean, cov = tr.A @ x0 + tr.b, tr.Q
    sd = np.sqrt(np.diag(cov))
    assert np.all(np.abs(paths.mean(axis=1) - mean) < 4 * sd / np.sqrt(n) + 0.01 * sd + 1e-9)
    sample_cov = np.cov(paths)
    se = np.sqrt((cov**2 + np.outer(np.diag(cov), np.diag(cov))) / n)  # sd of a Gaussian sample covariance
    assert np.all(np.abs(sample_cov - cov) < 4 * se + 0.02 * np.outer(sd, sd))


@pytest.mark.parametrize("name", sorted(CASES))
def test_k_day_transition_is_k_one_day_transitions_composed(name):
    """Chapman-Kolmogorov for a time-homogeneous linear-Gaussian Markov model: A_k = A^k,
    b_k = sum A^i b, Q_k = sum A^i Q A^i^T (i < k). A gap is one exact transition."""
    model = CASES[name]
    one, k = model.transition(1.0), 7
    a, b, q = np.eye(model.dim), np.zeros(model.dim), np.zeros((model.dim, model.dim))
    for _ in range(k):
        a, b, q = one.A @ a, one.A @ b + one.b, one.A @ q @ one.A.T + one.Q
    seven = model.transition(float(k))
    assert np.allclose(seven.A, a, atol=1e-12)
    assert np.allclose(seven.b, b, atol=1e-9)
    assert np.allclose(seven.Q, q, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("name", sorted(CASES))
def test_zero_interval_is_the_identity(name):
    tr = CASES[name].transition(0.0)
    assert np.allclose(tr.A, np.eye(tr.dim)) and np.allclose(tr.b, 0.0) and np.allclose(tr.Q, 0.0)
    w = tr.whitening(1e-3)  # Q = 0 is floored for the smoother's densities
    assert np.allclose(w @ (tr.Q + 1e-6 * np.eye(tr.dim)) @ w.T, np.eye(tr.dim), atol=1e-6)


@pytest.mark.parametrize("name", sorted(CASES))
def test_propagate_draws_from_the_transition(name):
    """From one state, 20,000 draws over 2.5 days: sample mean and covariance of the
    displacement (and velocity) in the start's tangent plane match A x + b and Q."""
    model = CASES[name]
    n, days = 20_000, 2.5
    velocity = np.tile([1.0, -2.0], (n, 1)) if model.has_velocity else None
    start = Particles(np.full(n, LAT0), np.full(n, LON0), velocity)
    moved = model.propagate(start, days, np.random.default_rng(8))
    east, north = local_offsets_km(moved.lat, moved.lon, LAT0, LON0)
    states = np.vstack([east, north] + ([moved.velocity_km_per_day.T] if model.has_velocity else []))
    tr = model.transition(days)
    x0 = np.zeros(model.dim)
    if model.has_velocity:
        x0[2:] = (1.0, -2.0)
    mean, cov = tr.A @ x0 + tr.b, tr.Q
    sd = np.sqrt(np.diag(cov))
    # The tangent plane is not flat: allow 0.2% of the displacement for the ellipsoid.
    assert np.all(np.abs(states.mean(axis=1) - mean) < 4 * sd / np.sqrt(n) + 2e-3 * np.abs(mean))
    se = np.sqrt((cov**2 + np.outer(np.diag(cov), np.diag(cov))) / n)
    assert np.all(np.abs(np.cov(states) - cov) < 4 * se + 1e-3 * np.outer(sd, sd))


@pytest.mark.parametrize("name", sorted(CASES))
def test_initial_cloud_about_the_launch_fix(name):
    model = CASES[name]
    cloud = model.initial(LAT0, LON0, 2.0, 20_000, np.random.default_rng(4))
    east, north = local_offsets_km(cloud.lat, cloud.lon, LAT0, LON0)
    assert np.std(east) == pytest.approx(2.0, rel=0.03) and np.std(north) == pytest.approx(2.0, rel=0.03)
    assert abs(np.mean(east)) < 0.05 and abs(np.mean(north)) < 0.05
    if model.has_velocity:
        mean, sd = model.stationary_velocity()
        v = cloud.velocity_km_per_day
        assert np.allclose(v.mean(axis=0), mean, atol=4 * sd / np.sqrt(20_000))
        assert np.allclose(v.std(axis=0), sd, rtol=0.03)
    else:
        assert cloud.velocity_km_per_day is None


def test_ou_limits_ballistic_then_diffusive():
    """D << T: the float moves with its velocity (x' ~ x + v D, tiny position noise);
    D >> T: per-axis variance grows as 2 sigma^2 T D (an effective diffusion)."""
    model = IntegratedOU(velocity_sd_km_per_day=4.0, decorrelation_days=10.0)
    short = model.transition(0.01)
    assert short.A[0, 2] == pytest.approx(0.01, rel=1e-3)
    assert short.Q[0, 0] == pytest.approx(2 * 16.0 * 0.01**3 / (3 * 10.0), rel=1e-2)  # 2 sigma^2 D^3 / (3 T)
    long_days = 2000.0
    assert model.transition(long_days).Q[0, 0] == pytest.approx(2 * 16.0 * 10.0 * long_days, rel=0.02)


# The float clock in the state (`motion.clock.ClockWalk`), about the OU drift with jumps.
CLOCKED = ClockWalk(JumpMixture(CASES["ou"], 0.05, 50.0), walk_s_per_sqrt_day=0.7, start_sd_s=1.5)


def test_clock_walk_draws_the_clock_as_a_random_walk_and_leaves_the_drift_alone():
    """From one state, 20,000 draws over 2.5 days: the clock's change is N(0, q^2 dt),
    independent of the position (correlation within 4 standard errors of 0), and the
    position and velocity are the drift's own draws (the same generator gives the same
    positions as the drift alone)."""
    n, days = 20_000, 2.5
    start = Particles(np.full(n, LAT0), np.full(n, LON0), np.tile([1.0, -2.0], (n, 1)), np.full(n, 3.0))
    moved = CLOCKED.propagate(start, days, np.random.default_rng(8))
    change = moved.clock_s - 3.0
    assert abs(change.mean()) < 4 * 0.7 * np.sqrt(days / n)
    assert change.std() == pytest.approx(0.7 * np.sqrt(days), rel=0.03)
    east, _ = local_offsets_km(moved.lat, moved.lon, LAT0, LON0)
    assert abs(np.corrcoef(east, change)[0, 1]) < 4 / np.sqrt(n)
    alone = CLOCKED.base.propagate(start, days, np.random.default_rng(8))
    assert np.array_equal(alone.lat, moved.lat) and np.array_equal(alone.velocity_km_per_day, moved.velocity_km_per_day)


def test_clock_walk_density_is_the_drift_s_times_the_clock_s_and_its_kernels_carry_the_clock():
    """log f(x', c' | x, c) = log f_drift(x' | x) + log N(c'; c, q^2 dt); each kernel of
    `components` is the drift's with the clock's block (1, q sqrt(dt)) appended, and its
    density of the appended state is that sum (the smoother's view of the same model)."""
    rng = np.random.default_rng(3)
    n, days = 50, 1.7
    start = CLOCKED.initial(LAT0, LON0, 3.0, n, rng)
    moved = CLOCKED.propagate(start, days, rng)
    drift = CLOCKED.base.log_transition(start, moved, days)
    sd = 0.7 * np.sqrt(days)
    clock = -0.5 * ((moved.clock_s - start.clock_s) / sd) ** 2 - np.log(sd * np.sqrt(2 * np.pi))
    assert np.allclose(CLOCKED.log_transition(start, moved, days), drift + clock)
    assert np.allclose(CLOCKED.log_carried_transition(start, moved, days), clock)
    a, b = CLOCKED.base.plane_states(start, moved)
    a, b = np.column_stack([a, start.clock_s]), np.column_stack([b, moved.clock_s])
    terms = [np.log(w) + k.log_density(a, b) for w, k in CLOCKED.components(days)]
    assert np.allclose(np.logaddexp.reduce(terms, axis=0), drift + clock)
    assert CLOCKED.dim == 5 and CLOCKED.transition(days).dim == 4
    assert isinstance(CLOCKED.reversed(), ClockWalk) and CLOCKED.reversed().walk_s_per_sqrt_day == 0.7


def test_clock_walk_starts_about_the_launch_clock():
    cloud = CLOCKED.initial(LAT0, LON0, 2.0, 20_000, np.random.default_rng(4))
    assert cloud.clock_s.std() == pytest.approx(1.5, rel=0.03) and abs(cloud.clock_s.mean()) < 4 * 1.5 / np.sqrt(20_000)
    east, _ = local_offsets_km(cloud.lat, cloud.lon, LAT0, LON0)
    assert np.std(east) == pytest.approx(2.0, rel=0.03)
