"""The binary sensor network and the multi-target simulator of the ABC paper (section 2).

Targets (eq. 1, F = I, Q = sigma^2 I, independent): with v_t the velocity of the step that
brings the target to x_t,
    v_t = v_{t-1} + N(0, sigma^2 I),    x_t = x_{t-1} + v_t,    t = 1..T (one step = 1 s).
(The paper writes x_t = x_{t-1} + v_{t-1}: the same process with v indexed one step
later; we index it by the step it drives, so that the sensors at t see the direction the
target is moving in when it reaches x_t.) Targets start at random angles on a circle of
radius 40 centred on 0, heading for the centre at `speed` units/s.

Sensors (eq. 2): sensor i at l_i reports, for each target j, the bit
    A_ij = 1{<x_t^j - l_i, v_t^j> < 0}   (target j is coming closer),
correct with probability pe (`p_correct`) and flipped otherwise, independently; it cannot
say which target a bit is about, so it reports only the count c_i = sum_j of its bits, in
0..Nt. With one target, c_i is the bit, and (eq. 6)
    log p(c | x, v) = sum_i log(pe if c_i = A_i else 1 - pe).
For Nt > 1 the paper calls the likelihood intractable (eq. 7); it is in fact the product
over sensors of Poisson-binomial pmfs (c_i is a sum of independent Bernoulli bits with
P(bit = 1) = pe A_ij + (1 - pe)(1 - A_ij)), computed exactly by `log_likelihood` with a
convolution over targets, O(Ns Nt^2); for Nt = 1 it is eq. 6.

Arrays: positions and velocities (..., Nt, 2); sensors (Ns, 2); bits (..., Ns, Nt);
counts (..., Ns).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

STEPS = 30  # seconds of tracking (paper section 5.2)
START_RADIUS = 40.0
VELOCITY_VAR = 0.1  # sigma^2 of eq. 1 (section 5.2)


def sensor_grid(n_sensors: int, half_width: float = 50.0) -> NDArray[np.float64]:
    """`n_sensors` (a square number) at the cell centres of a regular grid over
    [-half_width, half_width]^2, shape (Ns, 2). The paper does not give its layout."""
    side = round(float(np.sqrt(n_sensors)))
    if side * side != n_sensors:
        raise ValueError(f"n_sensors must be a square number, got {n_sensors}")
    ticks = -half_width + 2.0 * half_width * (np.arange(side) + 0.5) / side
    gx, gy = np.meshgrid(ticks, ticks)
    return np.column_stack([gx.ravel(), gy.ravel()])


def approaching(x: NDArray, v: NDArray, sensors: NDArray) -> NDArray[np.bool_]:
    """A_ij = 1{<x^j - l_i, v^j> < 0}: target j comes closer to sensor i; (..., Ns, Nt).

    Computed as <l_i, v^j> > <x^j, v^j> (no (..., Ns, Nt, 2) temporary)."""
    return np.swapaxes(_approaching_by_target(x, v, sensors), -1, -2)


def _approaching_by_target(x: NDArray, v: NDArray, sensors: NDArray) -> NDArray[np.bool_]:
    """A_ij laid out target-major, (..., Nt, Ns): sums over targets then add contiguous rows."""
    xv = (x * v).sum(axis=-1)  # (..., Nt)
    return np.asarray(v @ sensors.T > xv[..., None])


def reported_counts(bits: NDArray[np.bool_], p_correct: float, rng: np.random.Generator) -> NDArray[np.int64]:
    """c_i = sum_j of the bits A_ij, each flipped with probability 1 - pe; (..., Ns)."""
    flipped = rng.random(bits.shape, dtype=np.float32) >= np.float32(p_correct)
    return np.asarray((bits ^ flipped).sum(axis=-1), dtype=np.int64)


def simulate_counts(
    x: NDArray, v: NDArray, sensors: NDArray, p_correct: float, rng: np.random.Generator
) -> NDArray[np.int64]:
    """The model M of the paper: counts (..., Ns) that the network reports for targets at
    (x, v), sensor errors included (`reported_counts` on the bits, laid out target-major)."""
    bits = _approaching_by_target(x, v, sensors)
    reported = bits ^ (rng.random(bits.shape, dtype=np.float32) >= np.float32(p_correct))
    counts = reported[..., 0, :].astype(np.int64)
    for j in range(1, reported.shape[-2]):  # add the targets' rows (faster than a reduction)
        counts += reported[..., j, :]
    return counts


def log_likelihood(counts: NDArray, x: NDArray, v: NDArray, sensors: NDArray, p_correct: float) -> NDArray:
    """log p(c | x, v) (module docstring): eq. 6 for one target, the Poisson-binomial for
    more; `counts` (..., Ns) broadcast against states (..., Nt, 2). Returns shape (...)."""
    a = approaching(x, v, sensors)  # (..., Ns, Nt)
    n_targets = a.shape[-1]
    if n_targets == 1:  # eq. 6
        right = np.equal(counts, a[..., 0])
        return np.asarray(np.log(np.where(right, p_correct, 1.0 - p_correct)).sum(axis=-1))
    p_one = np.where(a, p_correct, 1.0 - p_correct)
    # pmf of the count over 0..Nt, built by adding one target at a time (log space).
    log_p1, log_p0 = np.log(p_one), np.log1p(-p_one)
    log_pmf = np.full((*a.shape[:-1], n_targets + 1), -np.inf)
    log_pmf[..., 0] = 0.0
    for j in range(n_targets):
        shifted = np.concatenate([np.full((*a.shape[:-1], 1), -np.inf), log_pmf[..., :-1]], axis=-1)
        log_pmf = np.logaddexp(log_pmf + log_p0[..., j, None], shifted + log_p1[..., j, None])
    shape = np.broadcast_shapes(np.shape(counts), a.shape[:-1])
    c = np.broadcast_to(np.asarray(counts, dtype=np.intp), shape)
    log_pmf = np.broadcast_to(log_pmf, (*shape, n_targets + 1))
    picked = np.take_along_axis(log_pmf, c[..., None], axis=-1)[..., 0]
    return np.asarray(picked.sum(axis=-1))


@dataclass(frozen=True)
class Truth:
    """Simulated targets and observations for a batch of independent scenarios.

    x, v: (R, T + 1, Nt, 2), index 0 the start; counts: (R, T + 1, Ns), row 0 unused (no
    observation at the start)."""

    x: NDArray[np.float64]
    v: NDArray[np.float64]
    counts: NDArray[np.int64]

    @property
    def steps(self) -> int:
        return self.x.shape[1] - 1


def simulate_targets(
    n_scenarios: int,
    n_targets: int,
    rng: np.random.Generator,
    *,
    steps: int = STEPS,
    radius: float = START_RADIUS,
    speed: float = 2.0,
    velocity_var: float = VELOCITY_VAR,
    angles: NDArray | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Tracks (x, v), each (R, T + 1, Nt, 2), from eq. 1: starts on the circle of `radius`
    at random angles (or `angles`, radians, (R, Nt)), heading for the centre at `speed`."""
    angle = rng.uniform(0.0, 2.0 * np.pi, (n_scenarios, n_targets)) if angles is None else np.asarray(angles)
    unit = np.stack([np.cos(angle), np.sin(angle)], axis=-1)
    noise = np.sqrt(velocity_var) * rng.standard_normal((n_scenarios, steps, n_targets, 2))
    v = np.concatenate([(-speed * unit)[:, None], -speed * unit[:, None] + np.cumsum(noise, axis=1)], axis=1)
    x = radius * unit[:, None] + np.concatenate([np.zeros_like(unit)[:, None], np.cumsum(v[:, 1:], axis=1)], axis=1)
    return x, v


def simulate_truth(
    n_scenarios: int,
    n_targets: int,
    sensors: NDArray,
    p_correct: float,
    rng: np.random.Generator,
    *,
    steps: int = STEPS,
    speed: float = 2.0,
    velocity_var: float = VELOCITY_VAR,
    angles: NDArray | None = None,
) -> Truth:
    """Targets (`simulate_targets`) and the counts the network reports."""
    x, v = simulate_targets(
        n_scenarios, n_targets, rng, steps=steps, speed=speed, velocity_var=velocity_var, angles=angles
    )
    counts = simulate_counts(x, v, sensors, p_correct, rng)
    counts[:, 0] = 0
    return Truth(x, v, counts)
