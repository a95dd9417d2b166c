"""Correlation height as source-vs-clutter evidence (`rafostrack.likelihoods.quality`)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.stats import norm

from rafostrack.config import load_config, with_overrides
from rafostrack.engines import exact
from rafostrack.likelihoods.quality import fit_quality, quality_log_ratio
from rafostrack.model import measurement as m

ON = dataclasses.replace(load_config().quality, enabled=True)


def test_off_by_default_and_without_heights():
    assert not load_config().quality.enabled
    assert np.all(quality_log_ratio([10.0, 80.0], load_config().quality) == 0)
    assert np.all(quality_log_ratio([np.nan, np.nan], ON) == 0)  # data without heights: no effect


def test_log_ratio_is_the_gaussian_density_ratio_capped():
    q = np.array([[20.0, 40.0], [60.0, np.nan]])
    expected = norm.logpdf(q, ON.source_mean, ON.source_sd) - norm.logpdf(q, ON.clutter_mean, ON.clutter_sd)
    expected = np.clip(np.nan_to_num(expected), -ON.max_abs_log_ratio, ON.max_abs_log_ratio)
    np.testing.assert_allclose(quality_log_ratio(q, ON), expected, rtol=1e-12)
    assert quality_log_ratio([500.0], ON)[0] == ON.max_abs_log_ratio


def test_posterior_from_the_ratio_is_calibrated():
    """Bayes with the ratio gives the frequency of sources among signals of a given height."""
    rng = np.random.default_rng(4)
    n, prior = 200_000, 0.6
    src = rng.random(n) < prior
    q = np.where(src, rng.normal(ON.source_mean, ON.source_sd, n), rng.normal(ON.clutter_mean, ON.clutter_sd, n))
    cfg = dataclasses.replace(ON, max_abs_log_ratio=50.0)
    p = 1.0 / (1.0 + np.exp(-(np.log(prior / (1 - prior)) + quality_log_ratio(q, cfg))))
    bins = np.digitize(p, np.linspace(0, 1, 11))
    for b in np.unique(bins):
        sel = bins == b
        if sel.sum() > 2000:
            assert src[sel].mean() == pytest.approx(p[sel].mean(), abs=0.02)


def test_fit_recovers_the_class_densities():
    rng = np.random.default_rng(5)
    src = rng.random(5000) < 0.7
    q = np.where(src, rng.normal(70, 15, 5000), rng.normal(30, 8, 5000))
    fit = fit_quality(q, src)
    assert fit is not None
    assert (fit.source_mean, fit.source_sd) == (pytest.approx(70, abs=1), pytest.approx(15, abs=1))
    assert (fit.clutter_mean, fit.clutter_sd) == (pytest.approx(30, abs=1), pytest.approx(8, abs=0.5))
    assert fit_quality(q[:10], src[:10]) is None


def test_quality_section_is_checked_like_any_other():
    from rafostrack.errors import InputError

    with pytest.raises(InputError, match=r"\[quality\] source_sd: must be > 0"):
        with_overrides(load_config(), quality={"source_sd": 0.0})


def test_heights_decide_between_two_equally_placed_signals():
    """Two signals equally far from the one beacon's prediction: without heights each is the
    beacon's half the time; a higher correlation height on the second makes it the source,
    by exactly the odds r_1 / r_0 (the association sum's two matchings)."""
    model = dataclasses.replace(load_config().model, echo_fraction=0.0, multipath_fraction=0.0)
    mu, toa = np.array([[1000.0]]), np.array([998.0, 1002.0])

    def p_source(ratio):
        f = m.association_factors(mu, np.array([[0.9]]), toa, max_signals=4, window_s=4200.0, model=model,
                                  source_log_ratio=ratio)  # fmt: skip
        return exact.associate(f.log_match, f.log_unheard).p_match[0, 0]

    plain = p_source(None)
    assert plain[0] == pytest.approx(plain[1])
    weighted = p_source(np.array([-1.0, 1.0]))
    assert weighted[1] / weighted[0] == pytest.approx(np.exp(2.0), rel=1e-9)
