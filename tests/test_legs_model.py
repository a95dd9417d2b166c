"""The leg model and prior: chaining, the renewal prior of the durations, the Jacobian."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import quad

from rafostrack.legs.model import (
    LegPrior,
    Legs,
    log_duration_prior,
    log_jacobian,
    log_prior,
    log_wrapped_normal,
    sample_prior,
    wrap_angle,
)


def test_from_parameters_chains_legs_end_to_start():
    legs = Legs.from_parameters((1.0, 2.0), 10.0, 40.0, [2.0, 1.0], [0.0, math.pi / 2], [10.0])
    np.testing.assert_allclose(legs.cuts, [10, 20, 40])
    np.testing.assert_allclose(legs.knots, [[1, 2], [21, 2], [21, 22]], atol=1e-12)
    np.testing.assert_allclose(legs.speeds, [2, 1])
    np.testing.assert_allclose(legs.headings, [0, math.pi / 2])


def test_from_parameters_refuses_legs_past_the_end():
    with pytest.raises(ValueError):
        Legs.from_parameters((0, 0), 0.0, 10.0, [1.0, 1.0], [0.0, 0.0], [12.0])


def test_wrapped_normal_integrates_to_one():
    for sd in (0.2, 1.0, 2.5):
        total, _ = quad(lambda a, sd=sd: float(np.exp(log_wrapped_normal(np.array(a), sd))), -math.pi, math.pi)
        assert total == pytest.approx(1.0, abs=1e-6)


def test_duration_prior_single_leg_is_the_survival_probability():
    prior = LegPrior(duration_min=5, duration_max=40)
    assert log_duration_prior(np.array([0.0, 3.0]), prior) == 0.0  # shorter than any leg: P = 1
    assert math.exp(log_duration_prior(np.array([0.0, 19.0]), prior)) == pytest.approx(21 / 35)
    assert log_duration_prior(np.array([0.0, 41.0]), prior) == -math.inf
    assert log_duration_prior(np.array([0.0, 4.0, 20.0]), prior) == -math.inf  # inner leg too short


def test_prior_draws_match_the_renewal_prior_of_k():
    """P(K = 1) over a span s in [t_min, t_max] is (t_max - s) / (t_max - t_min); P(K=2)
    integrates the first duration: int_{5}^{s-?} ... checked against quadrature."""
    prior = LegPrior(duration_min=5, duration_max=40)
    span = 30.0
    rng = np.random.default_rng(4)
    ks = np.array([sample_prior(prior, (0, 0), 0.0, span, rng).n_legs for _ in range(4000)])
    p1 = (40 - span) / 35
    # K = 2: first duration t in [5, span), then the second leg survives past span - t
    p2, _ = quad(lambda t: (1 / 35) * min(1.0, (40 - (span - t)) / 35), 5, span)
    assert np.mean(ks == 1) == pytest.approx(p1, abs=0.03)
    assert np.mean(ks == 2) == pytest.approx(p2, abs=0.03)


def test_log_prior_of_the_papers_defaults():
    prior = LegPrior()
    legs = Legs.from_parameters((0, 0), 0.0, 30.0, [12.5, 12.5], [0.3, 0.3], [20.0])
    expected = (
        -math.log(35)
        + math.log((40 - 10) / 35)
        + 2 * (-math.log(2 * math.sqrt(2 * math.pi)))
        - math.log(2 * math.pi)
        + float(log_wrapped_normal(np.array(0.0), math.pi / 12))
        - 2 * math.log(0.5 * (1 + math.erf(12.5 / 2 / math.sqrt(2))))
    )
    assert log_prior(legs, prior) == pytest.approx(expected)


def test_jacobian_matches_finite_differences():
    """|d(displacement)/d(speed, heading)| = t^2 w, per leg."""
    tau, w, a = 7.0, 3.0, 0.4
    eps = 1e-6

    def disp(w, a):
        return np.array([w * tau * math.cos(a), w * tau * math.sin(a)])

    jac = np.column_stack(
        [(disp(w + eps, a) - disp(w - eps, a)) / (2 * eps), (disp(w, a + eps) - disp(w, a - eps)) / (2 * eps)]
    )
    legs = Legs.from_parameters((0, 0), 0.0, tau, [w], [a], [])
    assert -log_jacobian(legs) == pytest.approx(math.log(abs(np.linalg.det(jac))), rel=1e-6)


def test_wrap_angle():
    np.testing.assert_allclose(
        wrap_angle(np.array([math.pi, -math.pi, 3 * math.pi / 2])), [-math.pi, -math.pi, -math.pi / 2]
    )
