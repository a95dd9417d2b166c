"""A plain particle filter on a plane, for the paper's synthetic experiments (section III).

State per particle: position (x, y) and velocity (vx, vy), in map units and units per time
step. Motion `ncv` (nearly constant velocity): x_t = x_t-1 + v_t-1 + a / 2, v_t = v_t-1 + a
with a white acceleration a ~ N(0, process_sd^2 I) per step (a target's sharp turns are what
this model does not capture); or `rw` (random walk): x_t = x_t-1 + N(0, process_sd^2 I).
Observations: position measurements z = x + N(0, sigma^2 I) from sensors, each seeing the
target only within its range. The filter is sequential importance resampling with the
bootstrap proposal: weights w_t = w_t-1 p(z_t | x_t) (the product over
the measurements at step t), systematic resampling (`rafostrack.filtering.resampling`) when the
effective sample size falls below `ess_fraction` N. Context (`rafostrack.context.rules`):
    none:   no CF;
    naive:  w_t *= CF(x_t) at every step;
    entry:  the paper's rule: w_t *= the CFs of the areas entered since x_t-1 when step t
            has a measurement; at a step without one, the particles that entered a new area
            are resampled by CF (`rules.resample_by_cf`).
The start counts as entering the first area. The estimate is the weighted mean; the paper's
RMSE is the cloud's, sqrt(sum_i W_i |x_t^i - x_t*|^2).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..filtering.resampling import ess, systematic
from .grid import ContextGrid
from .rules import entry_log_factor, naive_log_factor, resample_by_cf

RULES = ("none", "naive", "entry")


@dataclass(frozen=True)
class Sensor:
    """A position sensor at (x, y) seeing the target within `range_units` (inf: everywhere)."""

    x: float
    y: float
    range_units: float = float("inf")

    def sees(self, xy: NDArray[np.float64]) -> bool:
        return bool(np.hypot(xy[0] - self.x, xy[1] - self.y) <= self.range_units)


@dataclass(frozen=True)
class Measurement:
    step: int
    sensor: int
    z: NDArray[np.float64]  # (2,)


def polyline_truth(waypoints: Sequence[tuple[float, float]], n_steps: int) -> NDArray[np.float64]:
    """Positions at steps 0..n_steps of a target moving at constant speed along the polyline."""
    pts = np.asarray(waypoints, dtype=float)
    seg = np.hypot(*np.diff(pts, axis=0).T)
    at = np.concatenate([[0.0], np.cumsum(seg)])
    s = np.linspace(0.0, at[-1], n_steps + 1)
    return np.column_stack([np.interp(s, at, pts[:, 0]), np.interp(s, at, pts[:, 1])])


def simulate_measurements(
    truth: NDArray[np.float64], sensors: Sequence[Sensor], every: int, sigma: float, rng: np.random.Generator
) -> list[Measurement]:
    """Every `every` steps, one measurement from each sensor that sees the target (noise
    drawn per sensor in order, whether it sees the target or not)."""
    out = []
    for step in range(every, len(truth), every):
        noise = sigma * rng.standard_normal((len(sensors), 2))
        out += [Measurement(step, k, truth[step] + noise[k]) for k, s in enumerate(sensors) if s.sees(truth[step])]
    return out


def _normalised(log_w: NDArray[np.float64]) -> NDArray[np.float64]:
    """W = exp(log_w - max) / sum (NaN everywhere when no weight is finite)."""
    top = np.max(log_w)
    if not np.isfinite(top):
        return np.full(len(log_w), np.nan)
    w = np.exp(log_w - top)
    return w / w.sum()


@dataclass(frozen=True)
class PlanarFilter:
    """Bootstrap particle filter with nearly-constant-velocity motion (module docstring)."""

    grid: ContextGrid | None
    rule: str
    particles: int
    sigma: float
    process_sd: float
    ess_fraction: float = 0.5
    motion: str = "ncv"

    def __post_init__(self) -> None:
        if self.motion not in ("ncv", "rw"):
            raise ValueError(f"motion must be ncv or rw, got {self.motion!r}")
        if self.rule not in RULES:
            raise ValueError(f"rule must be one of {', '.join(RULES)}, got {self.rule!r}")
        if self.rule != "none" and self.grid is None:
            raise ValueError(f"rule {self.rule!r} needs a context grid")

    def run(
        self,
        n_steps: int,
        measurements: Sequence[Measurement],
        prior_xy: tuple[float, float],
        prior_sd: float,
        speed_sd: float,
        rng: np.random.Generator,
        truth: NDArray[np.float64] | None = None,
        snapshot_steps: Sequence[int] = (),
    ) -> PlanarRun:
        """Filter steps 0..n_steps; the per-step estimate, and the cloud RMSE when `truth` is given."""
        n = self.particles
        by_step: dict[int, list[Measurement]] = {}
        for m in measurements:
            by_step.setdefault(m.step, []).append(m)
        xy = np.asarray(prior_xy, dtype=float) + prior_sd * rng.standard_normal((n, 2))
        v = speed_sd * rng.standard_normal((n, 2))
        log_w = np.zeros(n)
        out = PlanarRun(n_steps)
        for t in range(n_steps + 1):
            before = xy
            if t > 0 and self.motion == "ncv":
                accel = self.process_sd * rng.standard_normal((n, 2))
                xy = xy + v + 0.5 * accel
                v = v + accel
            elif t > 0:
                xy = xy + self.process_sd * rng.standard_normal((n, 2))
            observed = by_step.get(t, [])
            for m in observed:
                log_w = log_w - 0.5 * ((xy - m.z) ** 2).sum(axis=1) / self.sigma**2
            if self.rule == "naive":
                log_w = log_w + naive_log_factor(self.grid, xy[:, 0], xy[:, 1])  # type: ignore[arg-type]
            elif self.rule == "entry":
                grid = self.grid
                assert grid is not None
                if t == 0:  # the start enters the first area
                    log_factor, entered = naive_log_factor(grid, xy[:, 0], xy[:, 1]), np.ones(n, dtype=bool)
                else:
                    log_factor, entered = entry_log_factor(grid, before[:, 0], before[:, 1], xy[:, 0], xy[:, 1])
                if observed:
                    log_w = log_w + log_factor
                elif entered.any():
                    index = self._resample_by_cf(log_w, log_factor, rng, out)
                    xy, v = xy[index], v[index]
            weights = _normalised(log_w)
            if not np.all(np.isfinite(weights)):  # every particle impossible: keep the cloud
                out.n_collapses += 1
                log_w = np.zeros(n)
                weights = np.full(n, 1.0 / n)
            out.record(t, xy, weights, truth)
            if t in snapshot_steps:
                out.snapshots[t] = (xy.copy(), weights.copy())
            if ess(weights) < self.ess_fraction * n:
                index = systematic(weights, rng)
                xy, v, log_w = xy[index], v[index], np.zeros(n)
                out.n_resamples += 1
        return out

    @staticmethod
    def _resample_by_cf(log_w, log_factor, rng: np.random.Generator, out: PlanarRun) -> NDArray[np.intp]:
        """Ancestors after resampling by CF (no measurement at this step)."""
        weights = _normalised(log_w)
        index, ok = resample_by_cf(weights, np.exp(log_factor), rng)
        out.n_cf_resamples += int((index != np.arange(len(index))).sum())
        out.n_collapses += 0 if ok else 1
        return index


@dataclass
class PlanarRun:
    """Per step: the weighted-mean estimate and the cloud RMSE; counts; particle snapshots."""

    n_steps: int
    estimate: NDArray[np.float64] = field(init=False)
    rmse: NDArray[np.float64] = field(init=False)
    n_resamples: int = 0
    n_cf_resamples: int = 0  # particles replaced by the resample-by-CF step
    n_collapses: int = 0  # steps where no particle was possible
    snapshots: dict[int, tuple[NDArray, NDArray]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.estimate = np.full((self.n_steps + 1, 2), np.nan)
        self.rmse = np.full(self.n_steps + 1, np.nan)

    def record(self, t: int, xy: NDArray, weights: NDArray, truth: NDArray | None) -> None:
        self.estimate[t] = np.einsum("p,pk->k", weights, xy)
        if truth is not None:
            self.rmse[t] = float(np.sqrt(np.einsum("p,p->", weights, ((xy - truth[t]) ** 2).sum(axis=1))))
