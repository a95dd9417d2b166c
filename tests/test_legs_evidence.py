"""Window likelihoods on grids: exact at nodes, bilinear between, penalised outside; fixes."""

from __future__ import annotations

import numpy as np
import pytest

from rafostrack.domain import Window
from rafostrack.legs.evidence import (
    FIX,
    WINDOW,
    Grids,
    build_grids,
    float_evidence,
    grid_loglik,
    smooth_grids,
    window_positions,
)
from rafostrack.legs.plane import Plane
from rafostrack.likelihoods import Evidence

PLANE = Plane(-57.0, -100.0)


class Quadratic:
    """A stand-in arrival likelihood: log p = -|x - c_j|^2 / 2 in plane km (c_j per window)."""

    def __init__(self, centres):
        self.centres = centres
        self.calls = 0

    def evaluate(self, particles, window, *, marginals=True):
        self.calls += 1
        j = int(window.toa_s[0])
        xy = PLANE.to_plane(particles.lat, particles.lon)
        return Evidence(-0.5 * ((xy - self.centres[j]) ** 2).sum(axis=1))


def _grids():
    truth = np.array([[10.0, -5.0], [40.0, 3.0]])
    windows = [
        Window(np.datetime64("2010-01-01"), np.array([0.0])),
        Window(np.datetime64("2010-01-02"), np.array([1.0])),
    ]
    lik = Quadratic(truth)
    centres = truth + np.array([[2.0, 1.0], [-3.0, 0.5]])
    return build_grids(lik, windows, centres, PLANE, 1.0, 6.0), lik, truth, centres  # type: ignore[arg-type]


def test_nodes_are_exact_and_one_call_per_window():
    grids, lik, truth, centres = _grids()
    assert lik.calls == 2 and grids.values.shape == (2, 13, 13)
    node = centres + np.array([[3.0, -2.0], [1.0, 4.0]])
    got = grid_loglik(grids, np.array([0, 1]), node, 3.0)
    np.testing.assert_allclose(got, -0.5 * ((node - truth) ** 2).sum(axis=1), atol=1e-6)


def test_bilinear_between_nodes_and_penalty_outside():
    grids, _, truth, centres = _grids()
    mid = centres[:1] + np.array([[0.5, 0.5]])
    corners = centres[0] + np.array([[0, 0], [1, 0], [0, 1], [1, 1]])
    want = np.mean(-0.5 * ((corners - truth[0]) ** 2).sum(axis=1))
    assert grid_loglik(grids, np.array([0]), mid, 3.0)[0] == pytest.approx(want, abs=1e-6)
    edge = centres[:1] + np.array([[6.0, 0.0]])
    far = centres[:1] + np.array([[9.0, 0.0]])
    drop = grid_loglik(grids, np.array([0]), edge, 3.0)[0] - grid_loglik(grids, np.array([0]), far, 3.0)[0]
    assert drop == pytest.approx(0.5 * (3.0 / 3.0) ** 2, abs=1e-6)


def test_float_evidence_orders_windows_and_fixes():
    grids, _, truth, _ = _grids()
    ev = float_evidence(
        np.array([1.0, 2.0]), grids, [(0.0, np.array([0.0, 0.0]), 2.0), (3.0, np.array([5.0, 5.0]), 1.0)], 3.0
    )
    np.testing.assert_array_equal(ev.times, [0, 1, 2, 3])
    np.testing.assert_array_equal(ev.kind, [FIX, WINDOW, WINDOW, FIX])
    xy = np.array([[1.0, 0.0], truth[0], truth[1], [5.0, 6.0]])
    terms = ev.terms(xy, slice(0, 4))
    assert terms[0] == pytest.approx(-0.5 * 1 / 4 - np.log(2 * np.pi * 4))
    assert terms[3] == pytest.approx(-0.5 - np.log(2 * np.pi))
    np.testing.assert_allclose(terms[1:3], [0.0, -0.125], atol=1e-6)  # the second sits between nodes
    np.testing.assert_allclose(ev.terms(xy[1:3], slice(1, 3)), terms[1:3])


def _gaussian_grid(centre, peak, sd, spacing=0.5, half=40):
    """A grid holding log N(x; peak, sd^2 I) about `centre`."""
    offsets = spacing * np.arange(-half, half + 1)
    de, dn = np.meshgrid(offsets, offsets, indexing="ij")
    values = -0.5 * ((centre[0] + de - peak[0]) ** 2 + (centre[1] + dn - peak[1]) ** 2) / sd**2
    return Grids(np.array([centre], dtype=float), spacing, values[None])


def test_smoothing_convolves_with_the_wiggle():
    """N(x; p, a^2) convolved with N(0, s^2): a Gaussian of variance a^2 + s^2 (up to a constant)."""
    grids = _gaussian_grid(np.array([0.0, 0.0]), np.array([1.0, -2.0]), 2.0)
    smooth = smooth_grids(grids, 3.0)
    z = np.array([[4.0, 1.0], [-3.0, -2.0], [1.0, -2.0]])
    got = grid_loglik(smooth, np.zeros(3, dtype=np.intp), z, 3.0)
    want = -0.5 * ((z - [1.0, -2.0]) ** 2).sum(axis=1) / 13.0
    np.testing.assert_allclose(got - got[2], want - want[2], atol=2e-3)
    assert smooth_grids(grids, 0.0) is grids


def test_position_given_the_leg_is_the_product_of_gaussians():
    """p(x | z) ~ N(x; p, a^2) N(x; z, s^2): mean (s^2 p + a^2 z) / (a^2 + s^2), variance a^2 s^2 / (a^2 + s^2)."""
    grids = _gaussian_grid(np.array([0.0, 0.0]), np.array([1.0, -2.0]), 2.0)
    z = np.array([[[3.0, 0.0]], [[0.0, -5.0]]])  # two samples, one window
    mean, cov = window_positions(grids, np.array([0]), z, 1.5)
    a2, s2 = 4.0, 2.25
    want = (s2 * np.array([1.0, -2.0]) + a2 * z[:, 0]) / (a2 + s2)
    np.testing.assert_allclose(mean[:, 0], want, atol=1e-3)
    np.testing.assert_allclose(cov[:, 0], np.broadcast_to(a2 * s2 / (a2 + s2) * np.eye(2), (2, 2, 2)), atol=1e-3)
    same, none = window_positions(grids, np.array([0]), z, 0.0)
    np.testing.assert_array_equal(same, z)
    np.testing.assert_array_equal(none, 0.0)
