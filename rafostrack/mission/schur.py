"""The mission's normal equations, block-arrow, solved by reduction to the array block.

Float f's own unknowns x_f (its nodes, banded, then its own statics) couple with nothing of
another float; every float couples with the array's unknowns theta (each source's offset,
drift, sound-speed deviation and position, the shared sound speed). The Gauss-Newton system

    [N_1              C_1 ] [dx_1 ]   [b_1  ]
    [      ...        ... ] [ ... ] = [ ... ]
    [            N_F  C_F ] [dx_F ]   [b_F  ]
    [C_1'  ...  C_F'   E  ] [dth  ]   [b_th ]

with E = P + sum_f E_f (P the array's prior information, E_f float f's own terms on the
array's columns) is solved as bundle adjustment solves its cameras and points: each x_f
eliminated on its own (its N_f is `BorderedBanded`: banded nodes, a dense border),

    S = P + sum_f (E_f - C_f' N_f^-1 C_f),    r = b_th + sum_f (b_f,th - C_f' N_f^-1 b_f),
    S dth = r,    dx_f = N_f^-1 (b_f - C_f dth).

Each float's reduction costs O(n_f w m_f) for its n_f unknowns, band half-width w and the
m_f array columns it touches; the array system O(M^3) once. S^-1 is the array's posterior
covariance (of the linearised model).

That covariance takes every arrival as independent; a float's arrivals are not (its track
and clock errors last for weeks, its multipath may be its own), so the floats, not the
arrivals, are the mission's independent units. The delete-one-float jackknife measures the
spread that follows (`ArraySolution.jackknife_covariance`): float f left out, the array's
Newton step from the same point is dth_(f) = (S - S_f)^-1 (r - r_f), with S_f, r_f the
float's reduced terms, and

    V_J = (F - 1) / F sum_f (dth_(f) - mean) (dth_(f) - mean)'

(Efron and Stein; for a least-squares fit it is the cluster-robust covariance, the floats
the clusters).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import sparse
from scipy.linalg import cho_factor, cho_solve
from scipy.stats import f as f_dist

from ..calibrate.banded import BorderedBanded, transposed_product

OUTLIER_ALPHA = 0.01  # `outlying`'s default: how often m equal Gaussian floats give an outlier
MIN_FLOATS_OUTLYING = 4


@dataclass(frozen=True)
class ReducedTerms:
    """A float's terms on theta with its own unknowns eliminated (`reduced_terms`)."""

    schur: NDArray[np.float64]  # (m_f, m_f) E_f - C_f' N_f^-1 C_f
    rhs: NDArray[np.float64]  # (m_f,) b_f,th - C_f' N_f^-1 b_f
    columns: NDArray[np.intp]  # (m_f,) index in theta

    def scattered(self, size: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The terms placed in theta's (size, size) system."""
        schur, rhs = np.zeros((size, size)), np.zeros(size)
        schur[np.ix_(self.columns, self.columns)] = self.schur
        np.add.at(rhs, self.columns, self.rhs)
        return schur, rhs


def reduced_terms(
    own: BorderedBanded, coupling: NDArray, corner: NDArray, own_rhs: NDArray, array_rhs: NDArray, columns: NDArray
) -> ReducedTerms:
    """E_f - C_f' N_f^-1 C_f and b_f,th - C_f' N_f^-1 b_f: a float's terms on theta with its
    own unknowns eliminated, each product as W'W with W = G_f^-1 [C_f, b_f] (N_f = G_f G_f',
    `BorderedBanded.whitened`; `banded.transposed_product`'s compiled sum, in a fixed order as einsum's)."""
    whitened = own.whitened(np.column_stack([coupling, own_rhs]))
    products = transposed_product(whitened, whitened)  # [W, w]'[W, w]: W'W, and W'w in its last column
    reduced = corner - products[:-1, :-1]
    return ReducedTerms(0.5 * (reduced + reduced.T), array_rhs - products[:-1, -1], columns)


@dataclass(frozen=True)
class FloatBlock:
    """One float's rows of the mission's normal equations: its own block N_f factored, its
    coupling C_f to the array columns it touches and its own right-hand side (for the
    back-substitution), and its reduced terms on theta (made with the block, in the process
    that linearised the float)."""

    own: BorderedBanded  # N_f
    # (n_f, m_f) C_f, sparse: a column is nonzero only at the nodes where its source is heard
    # (about a fifth), and the block crosses between processes at every step
    coupling: sparse.csr_matrix
    own_rhs: NDArray[np.float64]  # (n_f,) b_f
    terms: ReducedTerms  # its columns: where C_f's are in theta

    @classmethod
    def of(
        cls, normal: sparse.spmatrix, rhs: NDArray, n_band: int, bandwidth: int, n_own: int, columns: NDArray
    ) -> FloatBlock:
        """Split a float's normal matrix and right-hand side, ordered (its n_band banded
        unknowns, its other own unknowns up to n_own, then the array's), into the blocks."""
        normal = sparse.csr_matrix(normal)
        own = BorderedBanded(normal[:n_own, :n_own], n_band, bandwidth)
        coupling = normal[:n_own, n_own:]
        corner = normal[n_own:, n_own:].toarray()
        terms = reduced_terms(
            own, coupling.toarray(), corner, rhs[:n_own], rhs[n_own:], np.asarray(columns, dtype=np.intp)
        )
        return cls(own, coupling, rhs[:n_own], terms)

    def back_substituted(self, d_theta: NDArray) -> NDArray[np.float64]:
        """dx_f = N_f^-1 (b_f - C_f dth_f), dth_f the float's columns of dth."""
        return self.own.solve(self.own_rhs - self.coupling @ d_theta[self.terms.columns])


@dataclass(frozen=True)
class ArraySolution:
    """The mission system's solution: the array's step, each float's, S and r, S factored,
    and each float's reduced terms."""

    d_theta: NDArray[np.float64]
    d_own: list[NDArray[np.float64]]
    system: tuple[NDArray[np.float64], NDArray[np.float64]]  # S, r
    schur: tuple[NDArray[np.float64], bool]  # cho_factor of S
    terms: list[ReducedTerms]

    def covariance(self) -> NDArray[np.float64]:
        """S^-1: the array's posterior covariance (of the linearised model)."""
        return cho_solve(self.schur, np.eye(len(self.d_theta)))

    def left_out_steps(self) -> NDArray[np.float64]:
        """(F, M) the array's step with each float left out, dth_(f) = (S - S_f)^-1 (r - r_f)."""
        schur, rhs = self.system
        steps = np.empty((len(self.terms), len(rhs)))
        for k, terms in enumerate(self.terms):
            schur_f, rhs_f = terms.scattered(len(rhs))
            steps[k] = cho_solve(cho_factor(schur - schur_f, lower=True), rhs - rhs_f)
        return steps

    def jackknife_covariance(self, steps: NDArray | None = None) -> NDArray[np.float64]:
        """V_J (module docstring): the spread of the array's estimate over the floats left out
        in turn (`steps`, else `left_out_steps()`); zeros with fewer than two floats."""
        steps = self.left_out_steps() if steps is None else steps
        n = len(steps)
        if n < 2:
            return np.zeros((steps.shape[1], steps.shape[1]))
        centred = steps - steps.mean(axis=0)
        return (n - 1) / n * centred.T @ centred


def outlying(
    steps: NDArray, touching: NDArray[np.int64], alpha: float = OUTLIER_ALPHA
) -> tuple[NDArray[np.intp], NDArray[np.bool_]]:
    """Per column of `steps` (F, K), the float farthest from the others' mean, and whether it
    is an outlier among the m floats touching that unknown (`touching` (K,)): its squared
    deviation d^2 beyond what m equal Gaussian floats give at `alpha` over all m (a
    Grubbs test), d^2 / s^2 > m / (m - 1) F^-1(1 - alpha / m; 1, m - 2), s^2 the others' sum
    of squares over m - 2; never with fewer than four floats (`MIN_FLOATS_OUTLYING`)."""
    if len(steps) < 2:  # no others to compare with
        return np.zeros(steps.shape[1], dtype=np.intp), np.zeros(steps.shape[1], dtype=bool)
    farthest = np.argmax(np.abs(steps - steps.mean(axis=0)), axis=0)
    rest = np.where(np.arange(len(steps))[:, None] == farthest, np.nan, steps)
    rest_mean = np.nanmean(rest, axis=0)
    largest = (steps[farthest, np.arange(steps.shape[1])] - rest_mean) ** 2
    m = np.maximum(touching, MIN_FLOATS_OUTLYING).astype(float)
    threshold = m / (m - 1) * f_dist.ppf(1.0 - alpha / m, 1, m - 2)
    spread = np.maximum(np.nansum((rest - rest_mean) ** 2, axis=0) / (m - 2), np.finfo(float).tiny)
    return farthest, (touching >= MIN_FLOATS_OUTLYING) & (largest > threshold * spread)


def outlying_together(
    steps: NDArray, touching: NDArray[np.int64], alpha: float = OUTLIER_ALPHA
) -> tuple[NDArray[np.intp], NDArray[np.bool_]]:
    """`outlying` with every column tested at `alpha` over all the columns tested (those with
    `MIN_FLOATS_OUTLYING` floats or more; Bonferroni: each at alpha over their number), so
    that equal Gaussian floats give an outlier in any column on at most `alpha` of draws,
    however many columns there are."""
    tested = max(1, int(np.sum(touching >= MIN_FLOATS_OUTLYING)))
    return outlying(steps, touching, alpha / tested)


def array_system(
    terms: Sequence[ReducedTerms], prior_information: NDArray, prior_rhs: NDArray
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """S and r (module docstring): the floats' reduced terms added into the array's prior."""
    schur, rhs = np.array(prior_information, dtype=float), np.array(prior_rhs, dtype=float)
    for t in terms:
        schur[np.ix_(t.columns, t.columns)] += t.schur
        np.add.at(rhs, t.columns, t.rhs)
    return schur, rhs


def solve_mission(blocks: Sequence[FloatBlock], prior_information: NDArray, prior_rhs: NDArray) -> ArraySolution:
    """The whole system's solution: theta's from S, then each float's by back-substitution."""
    terms = [b.terms for b in blocks]
    schur, rhs = array_system(terms, prior_information, prior_rhs)
    factor = cho_factor(schur, lower=True)
    d_theta = cho_solve(factor, rhs)
    return ArraySolution(d_theta, [b.back_substituted(d_theta) for b in blocks], (schur, rhs), factor, terms)
