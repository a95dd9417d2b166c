"""Scores and likelihoods against scipy's densities."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from rafostrack.legs.scores import (
    GaussianLikelihood,
    Measurements,
    PaperScoreLikelihood,
    StudentLikelihood,
    paper_score,
)

DATA = Measurements(np.array([0.0, 1.0, 2.0]), np.array([[0.0, 0.0], [1.0, 1.0], [3.0, -1.0]]))
Z = np.array([[0.0, 1.0], [1.0, 1.0], [0.0, 3.0]])


def test_paper_score_is_the_summed_distance():
    assert paper_score(Z, DATA.xy) == pytest.approx(1.0 + 0.0 + 5.0)


def test_gaussian_terms_match_scipy():
    got = GaussianLikelihood(DATA, 2.0).terms(Z, slice(0, 3))
    want = stats.multivariate_normal(mean=[0, 0], cov=4 * np.eye(2)).logpdf(Z - DATA.xy)
    np.testing.assert_allclose(got, want)


def test_student_terms_match_scipy():
    got = StudentLikelihood(DATA, 2.0, dof=3.0).terms(Z[1:], slice(1, 3))
    want = stats.multivariate_t(loc=[0, 0], shape=4 * np.eye(2), df=3.0).logpdf(Z[1:] - DATA.xy[1:])
    np.testing.assert_allclose(got, want)


def test_paper_likelihood_is_the_score_over_two_sigma2():
    terms = PaperScoreLikelihood(DATA, 25.0).terms(Z, slice(0, 3))
    assert terms.sum() == pytest.approx(-paper_score(Z, DATA.xy) / 50.0)


def test_measurements_are_checked():
    with pytest.raises(ValueError):
        Measurements(np.array([1.0, 0.0]), np.zeros((2, 2)))
    with pytest.raises(ValueError):
        Measurements(np.array([0.0, 1.0]), np.zeros((3, 2)))
    assert math.isfinite(GaussianLikelihood(DATA, 1.0).terms(DATA.xy, slice(0, 3)).sum())
