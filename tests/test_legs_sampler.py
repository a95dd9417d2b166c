"""The sampler against a known posterior: one leg, Gaussian measurements.

With the start known, y_j = v t_j + e_j, e_j ~ N(0, sd^2 I), v = w (cos a, sin a): the
likelihood of (w, a) is exp(-sum_j |y_j - v t_j|^2 / (2 sd^2)) in closed form, the prior
N(w; mu, s^2) (truncated at 0) x U(a): the posterior of speed and heading by quadrature on
a fine grid is the oracle. The speed is small against its uncertainty, where the knot
move's Jacobian (1 / (t^2 w)) matters: leaving it out shifts the mean speed by ~0.5 sd.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from rafostrack.legs.model import LegPrior, Legs
from rafostrack.legs.sampler import SamplerConfig, repair_start, run_chain
from rafostrack.legs.scores import GaussianLikelihood, Measurements
from rafostrack.legs.summaries import circular_mean

PRIOR = LegPrior(speed_mean=2.0, speed_sd=2.0, duration_min=1.0, duration_max=100.0)
T = np.array([2.0, 4.0, 6.0, 8.0, 10.0])
SD = 15.0


def _data() -> Measurements:
    rng = np.random.default_rng(11)
    v = np.array([1.5, 0.8])
    return Measurements(T, T[:, None] * v + rng.normal(0, SD, (len(T), 2)))


def _oracle(data: Measurements) -> dict[str, float]:
    w = np.linspace(1e-4, 12.0, 1200)[:, None]
    a = np.linspace(-math.pi, math.pi, 1441)[None, :-1]
    vx, vy = w * np.cos(a), w * np.sin(a)
    sq = sum((data.xy[j, 0] - vx * t) ** 2 + (data.xy[j, 1] - vy * t) ** 2 for j, t in enumerate(data.times))
    logp = -0.5 * sq / SD**2 - 0.5 * ((w - PRIOR.speed_mean) / PRIOR.speed_sd) ** 2
    p = np.exp(logp - logp.max())
    p /= p.sum()
    pw, pa = p.sum(axis=1), p.sum(axis=0)
    mean_w = float((pw * w[:, 0]).sum())
    mean_a = float(np.angle((pa * np.exp(1j * a[0])).sum()))
    da = (a[0] - mean_a + math.pi) % (2 * math.pi) - math.pi
    return {
        "w": mean_w,
        "w_sd": float(np.sqrt((pw * (w[:, 0] - mean_w) ** 2).sum())),
        "a": mean_a,
        "a_sd": float(np.sqrt((pa * da**2).sum())),
    }


@pytest.mark.parametrize("moves", [{"leg": 1.0}, {"knot": 1.0}])
def test_one_leg_matches_the_analytic_posterior(moves):
    data = _data()
    oracle = _oracle(data)
    start = Legs(np.array([0.0, 10.0]), np.array([[0.0, 0.0], [15.0, 8.0]]))
    config = SamplerConfig(iterations=12000, moves=moves, max_kept=6000, knot_step=15.0, adapt=True)
    chain = run_chain(GaussianLikelihood(data, SD), PRIOR, start, config, np.random.default_rng(5), free_start=False)
    w = np.array([s.speeds[0] for s in chain.samples])
    a = np.array([s.headings[0] for s in chain.samples])
    assert np.all([s.knots[0] == 0 for s in chain.samples])
    assert w.mean() == pytest.approx(oracle["w"], abs=0.15 * oracle["w_sd"])
    assert w.std() == pytest.approx(oracle["w_sd"], rel=0.1)
    assert float(circular_mean(a)) == pytest.approx(oracle["a"], abs=0.15 * oracle["a_sd"])
    assert np.sqrt(np.mean(((a - oracle["a"] + math.pi) % (2 * math.pi) - math.pi) ** 2)) == pytest.approx(
        oracle["a_sd"], rel=0.12
    )


def test_same_seed_same_chain_and_stats():
    data = _data()
    start = Legs(np.array([0.0, 5.0, 10.0]), np.array([[0.0, 0.0], [8.0, 4.0], [15.0, 8.0]]))
    config = SamplerConfig(iterations=600, moves={"leg": 1, "knot": 1, "shift": 1, "start": 1, "jump": 1})
    one = run_chain(GaussianLikelihood(data, SD), PRIOR, start, config, np.random.default_rng(3))
    two = run_chain(GaussianLikelihood(data, SD), PRIOR, start, config, np.random.default_rng(3))
    assert len(one.samples) == 450
    for a, b in zip(one.samples, two.samples, strict=True):
        np.testing.assert_array_equal(a.knots, b.knots)
        np.testing.assert_array_equal(a.cuts, b.cuts)
    assert one.acceptance == two.acceptance and set(one.acceptance) == {"leg", "knot", "shift", "start", "jump"}
    assert one.best_log_posterior >= one.log_posterior.max()


def test_a_zero_length_leg_is_repaired_before_sampling():
    legs = Legs(np.array([0.0, 5.0, 10.0]), np.array([[0.0, 0.0], [0.0, 0.0], [5.0, 0.0]]))
    fixed = repair_start(legs, PRIOR)
    assert np.all(np.hypot(*fixed.displacements.T) > 0)
    with pytest.raises(ValueError):
        SamplerConfig(moves={"teleport": 1.0})


class Levels:
    """A likelihood with three levels whose terms do not depend on the trajectory: the level's
    posterior is prop. to exp(n_obs * c_level)."""

    times = np.array([1.0, 2.0, 3.0, 4.0])
    n_levels = 3
    start_level = 0
    offsets = np.array([0.0, 0.5, 0.25])

    def terms(self, xy, index, level=0):
        return np.full(len(xy), self.offsets[level])


def test_level_move_samples_the_levels_posterior():
    start = Legs(np.array([0.0, 4.0]), np.array([[0.0, 0.0], [8.0, 0.0]]))
    config = SamplerConfig(iterations=12000, moves={"level": 1.0}, max_kept=12000)
    chain = run_chain(Levels(), PRIOR, start, config, np.random.default_rng(4), free_start=False)
    want = np.exp(4 * Levels.offsets)
    want /= want.sum()
    np.testing.assert_allclose(np.bincount(chain.levels, minlength=3) / len(chain.levels), want, atol=0.03)
