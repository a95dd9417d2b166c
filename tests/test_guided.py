"""The proposal guided by the window (`rafostrack.filtering.guided`): its Gaussian summary, its
density against a dense product of Gaussians, its optimality, and a filter that uses it."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.stats import multivariate_normal

from rafostrack.config import load_config, with_overrides
from rafostrack.domain import Particles
from rafostrack.filtering.guided import GuidedDrift, LikelihoodSummary, summarise_likelihood
from rafostrack.model.geodesy import local_offsets_km
from rafostrack.motion.ou import IntegratedOU
from rafostrack.motion.random_walk import RandomWalk
from rafostrack.problem import FloatProblem
from rafostrack.run.one_pass import Tracker
from rafostrack.summaries.estimates import build_estimate

CENTRE = (-55.02, -59.95)  # the Gaussian likelihood's peak
PRECISION = np.array([[1 / 1.5**2, 0.1], [0.1, 1.0]])  # 1/km^2: sd 1.5 km east, 1 km north, correlated


def _gaussian_loglik(particles: Particles) -> np.ndarray:
    east, north = local_offsets_km(particles.lat, particles.lon, *CENTRE)
    y = np.column_stack([east, north])
    return -0.5 * np.einsum("pi,ij,pj->p", y, PRECISION, y)


def _cloud(motion, n: int, seed: int) -> tuple[Particles, Particles]:
    rng = np.random.default_rng(seed)
    ancestors = motion.initial(-55.0, -60.0, 3.0, n, rng)
    return ancestors, motion.propagate(ancestors, 1.0, rng)


def test_summary_recovers_a_gaussian_likelihood():
    """Fitted to an exactly Gaussian log-likelihood, the summary has its precision and its
    peak (eta = Lambda y_peak in the summary's plane) to round-off of the planes' mapping."""
    _, moved = _cloud(IntegratedOU(4.0, 3.0), 2000, 0)
    summary = summarise_likelihood(moved, np.full(len(moved), 1 / len(moved)), _gaussian_loglik(moved))
    assert summary is not None
    np.testing.assert_allclose(summary.precision, PRECISION, rtol=2e-3, atol=1e-4)
    peak = np.linalg.solve(summary.precision, summary.shift)
    expected = local_offsets_km(*CENTRE, summary.lat0, summary.lon0)
    np.testing.assert_allclose(peak, expected, atol=0.02)


def test_summary_is_none_without_enough_pilot_or_sharpening():
    _, moved = _cloud(IntegratedOU(4.0, 3.0), 500, 1)
    uniform = np.full(len(moved), 1 / len(moved))
    assert summarise_likelihood(moved, uniform, np.zeros(len(moved))) is None  # flat: sharpens nothing
    spiky = np.where(np.arange(len(moved)) < 10, 0.0, -50.0)  # ~10 particles carry the posterior
    assert summarise_likelihood(moved, uniform, spiky) is None


def _dense_moments(motion, dt: float, summary: LikelihoodSummary, ancestors: Particles):
    """The oracle: mean and covariance of N(A x_i + b, Q) exp(eta' y - y' Lambda y / 2) in
    each ancestor's plane, from dense inverses of Q and the information matrix."""
    tr = motion.transition(dt)
    h = np.eye(2, tr.dim)
    cov = np.linalg.inv(np.linalg.inv(tr.Q) + h.T @ summary.precision @ h)
    origin = np.column_stack(local_offsets_km(ancestors.lat, ancestors.lon, summary.lat0, summary.lon0))
    means = []
    for i in range(len(ancestors)):
        x = np.zeros(tr.dim)
        if tr.dim == 4:
            x[2:] = ancestors.velocity_km_per_day[i]
        information = np.linalg.solve(tr.Q, tr.A @ x + tr.b) + h.T @ (summary.shift - summary.precision @ origin[i])
        means.append(cov @ information)
    return np.array(means), cov


@pytest.mark.parametrize("motion", [IntegratedOU(4.0, 3.0, (2.0, -1.0)), RandomWalk(3.0)], ids=["ou", "random_walk"])
@pytest.mark.parametrize("rank", [2, 1])
def test_guided_density_is_the_dense_product_of_drift_and_summary(motion, rank):
    """log q_i at draws from five ancestors: full-rank and rank-1 Lambda (a window that
    sharpens one direction only)."""
    ancestors, _ = _cloud(motion, 5, 2)
    precision = PRECISION if rank == 2 else np.outer([0.6, 0.8], [0.6, 0.8]) / 1.2**2
    summary = LikelihoodSummary(-55.01, -59.97, precision, precision @ np.array([1.0, -2.0]))
    guided = GuidedDrift(motion, 1.5, summary)
    drawn = guided.sample(ancestors, np.random.default_rng(3))
    _, states = motion.plane_states(ancestors, drawn)
    means, cov = _dense_moments(motion, 1.5, summary, ancestors)
    expected = [multivariate_normal(m, cov).logpdf(x) for m, x in zip(means, states, strict=True)]
    np.testing.assert_allclose(guided.log_density(ancestors, drawn), expected, rtol=1e-8, atol=1e-8)


def test_guided_draws_have_the_moments_of_the_dense_product():
    """200,000 draws from one ancestor: mean within 4 standard errors, covariance within
    2% of the oracle's (sample and log_density describe the same law)."""
    motion = IntegratedOU(4.0, 3.0)
    ancestors, _ = _cloud(motion, 1, 4)
    summary = LikelihoodSummary(-55.01, -59.97, PRECISION, PRECISION @ np.array([1.0, -2.0]))
    n = 200_000
    many = ancestors.take(np.zeros(n, dtype=np.intp))
    _, states = motion.plane_states(many, GuidedDrift(motion, 1.0, summary).sample(many, np.random.default_rng(5)))
    means, cov = _dense_moments(motion, 1.0, summary, ancestors)
    sd = np.sqrt(np.diag(cov))
    assert np.all(np.abs(states.mean(axis=0) - means[0]) < 4 * sd / np.sqrt(n))
    np.testing.assert_allclose(np.cov(states.T), cov, rtol=0.02, atol=0.02 * np.outer(sd, sd).max())


def test_guided_weights_are_constant_per_ancestor_for_a_gaussian_likelihood():
    """Where the likelihood is the summary's Gaussian, q_i is the locally optimal proposal:
    p(y | x') f(x' | x_i) / q_i(x') does not depend on the draw x' (it is the ancestor's
    predictive likelihood), so the guided draws of one ancestor are equally weighted;
    the drift's own draws (the bootstrap filter) are not."""
    motion = IntegratedOU(4.0, 3.0)
    ancestors, moved = _cloud(motion, 2000, 6)
    summary = summarise_likelihood(moved, np.full(len(moved), 1 / len(moved)), _gaussian_loglik(moved))
    guided = GuidedDrift(motion, 1.0, summary)
    one = ancestors.take(np.zeros(1000, dtype=np.intp))
    rng = np.random.default_rng(7)
    drawn = guided.sample(one, rng)
    log_w = _gaussian_loglik(drawn) + motion.log_transition(one, drawn, 1.0) - guided.log_density(one, drawn)
    assert np.std(log_w) < 1e-3
    assert np.std(_gaussian_loglik(motion.propagate(one, 1.0, rng))) > 0.5


def test_guiding_leaves_the_posterior_unchanged_and_raises_the_ess(sim_mission):
    """The filter with half of each window's cloud guided, weighted by the mixture, gives
    the bootstrap filter's posterior within Monte Carlo error (as the re-seeding test in
    test_recovery.py: median shift under 0.15 posterior sd, the same spread within 5%),
    with a higher ESS. Guided draws weighted as if they came from the drift pull the cloud
    onto the likelihood's peak: its sd falls by 9% (median), and the test fails."""
    sim = sim_mission.floats[0]
    record = dataclasses.replace(sim.record, windows=sim.record.windows[:25])
    config = with_overrides(
        load_config(),
        calibrate={"enabled": False},
        smoother={"enabled": False},
        recovery={"enabled": False},
        filter={"particles": 2000},
        motion={"velocity_sd_km_per_day": 4.0},
    )
    runs, tracks = [], []
    for fraction in (0.0, 0.5):
        tracker = Tracker.from_problem(
            FloatProblem(sim_mission.beacons, sim.info, with_overrides(config, filter={"guided_fraction": fraction}))
        )
        run = tracker.run_filter(record)
        runs.append(run)
        tracks.append(
            build_estimate(sim.info.float_id, run.steps, sim_mission.beacons.beacon_id, config.ambiguity).track
        )
    east, north = local_offsets_km(tracks[1]["lat"], tracks[1]["lon"], tracks[0]["lat"], tracks[0]["lon"])
    shift = np.hypot(east, north) / tracks[0]["sd_km"].to_numpy()
    assert np.median(shift) < 0.15 and shift.max() < 1.2, np.round(shift, 2)
    ratio = tracks[1]["sd_km"].to_numpy() / tracks[0]["sd_km"].to_numpy()
    assert 0.95 < np.median(ratio) < 1.05, np.round(ratio, 2)  # 0.91 without the mixture's weights
    ess = [np.median([s.ess for s in run.steps]) for run in runs]
    assert ess[1] > 1.2 * ess[0], ess  # 556 and 727 of 2000
