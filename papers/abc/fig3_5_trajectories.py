"""Paper Figs. 3-5: ABC-RW's particles on two scenarios, 64 sensors.

- Fig. 3: five targets starting close together (on an arc of the circle, 6 degrees apart),
  sigma_v = 0.1, start known within 10 units (error uniform in a disc of radius 10), chains
  of 5000 iterations of which the last 250 of each step are drawn.
- Figs. 4-5: three targets at random angles, sigma_v = 0.3, chains of 10000 iterations
  (the paper reports an acceptance rate of about 0.12); Fig. 4 shows the particles and the
  histograms of their bearings (direction of motion, degrees anticlockwise from east) at
  two times (t = 5 and 15 s), Fig. 5 the particles' bearings over the whole path with the
  true ones, steps where no state came within the tolerance shaded (the nearest draws are
  drawn there).
(sigma_v read as the sd of the velocity increments, as the paper writes it for these figures.)

    python -m papers.abc --only fig3_5_trajectories [--quick] [--out DIR]
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from rafostrack.plots import save_png
from rafostrack.sensors import Settings, TrackResult, Truth, rmse, sensor_grid, simulate_truth, track

from ..common import DEFAULT_WORKERS, experiment, figure, pmap
from .setting import HALF_WIDTH, INIT_VELOCITY_SD, P_CORRECT, SPEED, TIMES

NAME = "fig3_5_trajectories"
N_SENSORS = 64
COLORS = ("tab:green", "tab:blue", "tab:red", "tab:purple", "tab:orange")
SNAPSHOTS_T = (5, 15)  # Fig. 4: early, and after the targets have met near the centre


@dataclass(frozen=True)
class Sizes:
    iterations_fig3: int = 5000
    iterations_fig45: int = 10000
    shown_fig3: int = 250
    kept_fig45: int = 1000


FULL = Sizes()
QUICK = Sizes(iterations_fig3=800, iterations_fig45=1500, shown_fig3=250, kept_fig45=500)
SEED = 3


def _scenario(task: tuple[str, int, Sizes]) -> tuple[Truth, TrackResult]:
    """One scenario ('fig3' or 'fig45') tracked by ABC-RW."""
    which, seed, sz = task
    rng = np.random.default_rng([seed, 0 if which == "fig3" else 1])
    sensors = sensor_grid(N_SENSORS, HALF_WIDTH)
    if which == "fig3":
        base = rng.uniform(0, 2 * np.pi)
        angles = (base + np.radians(6.0) * (np.arange(5) - 2))[None]
        truth = simulate_truth(1, 5, sensors, P_CORRECT, rng, speed=SPEED, velocity_var=0.1**2, angles=angles)
        r, a = 10.0 * np.sqrt(rng.random((1, 5))), rng.uniform(0, 2 * np.pi, (1, 5))
        x0 = truth.x[:, 0] + np.stack([r * np.cos(a), r * np.sin(a)], axis=-1)
        settings = Settings("rw", particles=sz.iterations_fig3, p_correct=P_CORRECT, velocity_var=0.1**2,
                            keep=sz.shown_fig3)  # fmt: skip
    else:
        truth = simulate_truth(1, 3, sensors, P_CORRECT, rng, speed=SPEED, velocity_var=0.3**2)
        x0 = truth.x[:, 0] + rng.standard_normal(truth.x[:, 0].shape)
        settings = Settings("rw", particles=sz.iterations_fig45, p_correct=P_CORRECT, velocity_var=0.3**2,
                            keep=sz.kept_fig45)  # fmt: skip
    v0 = truth.v[:, 0] + INIT_VELOCITY_SD * rng.standard_normal(truth.v[:, 0].shape)
    return truth, track(truth, sensors, x0, v0, settings, rng)


def bearing_deg(v: NDArray) -> NDArray[np.float64]:
    """Direction of motion, degrees anticlockwise from east."""
    return np.asarray(np.degrees(np.arctan2(v[..., 1], v[..., 0])))


def _wrap(deg: NDArray) -> NDArray[np.float64]:
    return np.asarray((deg + 180.0) % 360.0 - 180.0)


@experiment(FULL, QUICK)
def run(outdir: Path, sz: Sizes, *, seed: int = SEED, workers: int = DEFAULT_WORKERS) -> dict[str, Any]:
    """Write the three figures and the summary into `outdir`."""
    (truth3, res3), (truth45, res45) = pmap(_scenario, [("fig3", seed, sz), ("fig45", seed, sz)], workers)
    files = ["fig3_five_targets.png", "fig4_bearings_at_t.png", "fig5_bearings_path.png"]
    _draw_fig3(outdir / files[0], truth3, res3, sz)
    velocities = [s - res45.x_hat[:, t, None] for t, s in enumerate(res45.samples)]  # theta = x_t - x^_{t-1}
    _draw_fig4(outdir / files[1], truth45, res45, velocities)
    _draw_fig5(outdir / files[2], truth45, velocities, res45.fallback[0])
    summary: dict[str, Any] = {"name": NAME, "title": "Figs. 3-5, ABC-RW's particles", "files": files, "seed": seed}
    for key, truth, res, iterations in (("fig3", truth3, res3, sz.iterations_fig3),
                                        ("fig45", truth45, res45, sz.iterations_fig45)):  # fmt: skip
        err = rmse(res.x_hat, truth.x)[0]
        summary[key] = {
            "targets": int(truth.x.shape[2]),
            "iterations": iterations,
            "acceptance": float(res.acceptance.mean()),
            "fallback_steps": int(res.fallback.sum()),
            "tolerance": res.tolerance,
            "rmse": {str(t): float(err[t]) for t in TIMES},
            "seconds": res.seconds,
        }
    true_b = bearing_deg(truth45.v[0, 1:])  # (T, Nt)
    spread = [float(np.mean(np.abs(_wrap(bearing_deg(v[0]) - true_b[t][None])))) for t, v in enumerate(velocities)]
    summary["fig45"]["mean_abs_bearing_error_deg"] = float(np.mean(spread))
    return summary


def _draw_fig3(path: Path, truth: Truth, res: TrackResult, sz: Sizes) -> None:
    sensors = sensor_grid(N_SENSORS, HALF_WIDTH)
    with figure(12.0, 5.8) as fig:
        axes = fig.subplots(1, 2, sharex=True, sharey=True)
        for ax in axes:
            ax.scatter(sensors[:, 0], sensors[:, 1], marker="s", s=10, color="0.75", zorder=0)
            ax.set_aspect("equal")
            ax.grid(True, lw=0.3, alpha=0.4)
        for j in range(truth.x.shape[2]):
            c = COLORS[j % len(COLORS)]
            axes[0].plot(truth.x[0, :, j, 0], truth.x[0, :, j, 1], color=c, lw=1.5, marker=".", ms=4)
            pts = np.concatenate([s[0, :, j] for s in res.samples])
            axes[1].scatter(pts[:, 0], pts[:, 1], s=1.5, color=c, alpha=0.15, lw=0)
            axes[1].plot(truth.x[0, :, j, 0], truth.x[0, :, j, 1], color="k", lw=0.7)
            axes[1].plot(res.x_hat[0, :, j, 0], res.x_hat[0, :, j, 1], color=c, lw=1.0, ls="--")
        axes[0].set_title("true trajectories (sensors: grey squares)", fontsize=10)
        axes[1].set_title(
            f"ABC-RW: last {sz.shown_fig3} of {sz.iterations_fig3} states per step (dots), estimate (dashed), "
            "truth (black)",
            fontsize=9,
        )
        fig.suptitle(f"Fig. 3: five close targets, sigma_v = 0.1, acceptance {res.acceptance.mean():.2f}", fontsize=11)
        save_png(fig, path)


def _draw_fig4(path: Path, truth: Truth, res: TrackResult, velocities: list[NDArray]) -> None:
    n_targets = truth.x.shape[2]
    with figure(13.0, 8.6) as fig:
        axes = fig.subplots(len(SNAPSHOTS_T), n_targets + 1, squeeze=False)
        for row, t in zip(axes, SNAPSHOTS_T, strict=True):
            theta = velocities[t - 1]
            ax = row[0]
            for j in range(n_targets):
                c = COLORS[j]
                ax.plot(truth.x[0, : t + 1, j, 0], truth.x[0, : t + 1, j, 1], color=c, lw=1.2)
                pts = res.x_hat[0, t - 1, j] + theta[0, :, j]
                ax.scatter(pts[:, 0], pts[:, 1], s=2, color=c, alpha=0.2, lw=0)
                ax.plot(*truth.x[0, t, j], marker="*", color="k", ms=8)
            ax.set_aspect("equal")
            note = "; none within epsilon: nearest draws" if res.fallback[0, t - 1] else ""
            ax.set_title(f"t = {t} s (star: truth{note})", fontsize=8)
            for j in range(n_targets):
                ax = row[j + 1]
                b = bearing_deg(theta[0, :, j])
                true_b = float(bearing_deg(truth.v[0, t, j]))
                ax.hist(true_b + _wrap(b - true_b), bins=30, color=COLORS[j], alpha=0.7)
                ax.axvline(true_b, color="k", lw=1.5)
                ax.set_title(f"t = {t} s, target {j + 1}: bearing (deg), true in black", fontsize=8)
        fig.suptitle("Fig. 4: ABC-RW, three targets, sigma_v = 0.3: particles and their bearings", fontsize=11)
        save_png(fig, path)


def _draw_fig5(path: Path, truth: Truth, velocities: list[NDArray], fallback: NDArray) -> None:
    n_targets = truth.x.shape[2]
    with figure(11.0, 5.0) as fig:
        ax = fig.subplots()
        for stalled in np.flatnonzero(fallback) + 1:
            ax.axvspan(stalled - 0.5, stalled + 0.5, color="0.9", lw=0)
        for j in range(n_targets):
            c = COLORS[j]
            true_b = bearing_deg(truth.v[0, 1:, j])
            b = np.array(
                [true_b[t] + _wrap(bearing_deg(theta[0, :, j]) - true_b[t]) for t, theta in enumerate(velocities)]
            )
            times = np.broadcast_to(np.arange(1, len(velocities) + 1)[:, None] + 0.25 * (j - 1), b.shape)
            ax.scatter(times.ravel(), b.ravel(), s=1, color=c, alpha=0.08, lw=0)
            ax.plot(np.arange(1, len(true_b) + 1), true_b, color=c, lw=2, label=f"target {j + 1}, true bearing")
        ax.set_xlabel("time (s); shaded: no state within epsilon (nearest draws shown)")
        ax.set_ylabel("bearing (degrees anticlockwise from east)")
        ax.grid(True, lw=0.4, alpha=0.5)
        ax.legend(fontsize=8, frameon=False)
        ax.set_title("Fig. 5: ABC-RW particles' bearings along the path (dots) and the true bearings", fontsize=10)
        save_png(fig, path)
