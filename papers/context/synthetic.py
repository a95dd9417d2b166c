"""Experiments A, B and C of the paper (Figs. 4-6): the synthetic map, repeated runs, and
the figures and table they share.

One repetition draws the measurements (sensors, every 50 steps, sigma 10) and runs the
filter once per compared rule with the same filter seed (common random numbers). Per rule:
the cloud RMSE per step (the paper's), its mean over the run and over steps 0-700 (the
south-western marsh, where the paper sees the naive rule fail), and the mean error of the
weighted-mean estimate. The table gives the mean over repetitions with its standard error.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.colors import ListedColormap
from matplotlib.patches import Circle

from rafostrack.context.planar import PlanarFilter, Sensor, simulate_measurements
from rafostrack.plots import save_png

from ..common import figure, mean_se, pmap, save_csv
from .setting import EVERY, N_STEPS, SIGMA, START, FilterSettings, context_grid, truth_track

MARSH_STEPS = 700  # the paper's "between steps 0 and 700"
COLORS = {"none": "tab:orange", "naive": "tab:red", "entry": "tab:green"}
LABELS = {"none": "no context", "naive": "context at every step (naive)", "entry": "context at cell entry"}
CF_CMAP = ListedColormap(["0.35", "0.78", "1.0"])  # CF 0 dark grey, 0.5 light grey, 1 white


@dataclass(frozen=True)
class Sizes:
    repeats: int
    particles: int


FULL = Sizes(repeats=30, particles=1000)
QUICK = Sizes(repeats=4, particles=300)


def _one_repeat(task: tuple[int, int, tuple[str, ...], tuple[Sensor, ...], int, bool]) -> dict[str, Any]:
    """One repetition: measurements, then each rule's filter (same seed for all)."""
    seed, rep, rules, sensors, particles, snapshots = task
    grid, truth, fs = context_grid(), truth_track(), FilterSettings()
    meas = simulate_measurements(truth, sensors, EVERY, SIGMA, np.random.default_rng([seed, rep, 0]))
    out: dict[str, Any] = {"measurements": np.array([[m.step, *m.z] for m in meas]).reshape(-1, 3)}
    for rule in rules:
        pf = PlanarFilter(None if rule == "none" else grid, rule, particles, SIGMA, fs.accel_sd)
        rng = np.random.default_rng([seed, rep, 1])
        snap = (1000, 2000) if rep == 0 and snapshots else ()
        run = pf.run(N_STEPS, meas, START, fs.prior_sd, fs.speed_sd, rng, truth=truth, snapshot_steps=snap)
        out[rule] = run
    return out


def run_comparison(
    name: str, title: str, outdir: Path, sz: Sizes, rules: tuple[str, ...], sensors: tuple[Sensor, ...], *,
    seed: int, workers: int, claim: str, snapshots: bool = False,
) -> dict[str, Any]:  # fmt: skip
    """Run `sz.repeats` repetitions, write `<name>.png` (tracks and RMSE curves) and the CSVs,
    and return the summary with the table."""
    tasks = [(seed, rep, rules, sensors, sz.particles, snapshots) for rep in range(sz.repeats)]
    reps = pmap(_one_repeat, tasks, workers)
    truth = truth_track()
    steps = np.arange(N_STEPS + 1)
    rmse = {r: np.array([rep[r].rmse for rep in reps]) for r in rules}  # (repeats, steps)
    err = {r: np.array([np.hypot(*(rep[r].estimate - truth).T) for rep in reps]) for r in rules}
    seen = np.array([any(s.sees(p) for s in sensors) for p in truth])
    table = {r: _rule_table(rmse[r], err[r], seen, [rep[r] for rep in reps]) for r in rules}
    base = rules[0]
    paired = {r: _paired(rmse[r], rmse[base]) for r in rules[1:]}
    curves = pd.DataFrame({"step": steps, **{f"rmse_{r}": rmse[r].mean(axis=0) for r in rules}})
    first = reps[0]
    track = pd.DataFrame(
        {"step": steps, "x_true": truth[:, 0], "y_true": truth[:, 1]}
        | {f"{a}_{r}": first[r].estimate[:, k] for r in rules for k, a in enumerate("xy")}
    )
    files = [f"{name}.png", f"{name}_rmse.csv", f"{name}_track.csv"]
    save_csv(curves, outdir / files[1])
    save_csv(track, outdir / files[2])
    _draw(outdir / files[0], title, rules, sensors, first, truth, curves, rmse)
    if snapshots:
        files.append(f"{name}_particles.png")
        _draw_particles(outdir / files[-1], rules, sensors, first, truth)
    return {
        "name": name,
        "title": title,
        "claim": claim,
        "files": files,
        "seed": seed,
        "repeats": sz.repeats,
        "particles": sz.particles,
        "steps": N_STEPS,
        "unseen_steps": int((~seen).sum()),
        "every": EVERY,
        "sigma": SIGMA,
        "rules": list(rules),
        "sensors": [{"x": s.x, "y": s.y, "range": s.range_units} for s in sensors],
        "filter": FilterSettings().describe(),
        "table": table,
        "paired_vs_" + base: paired,
    }


def _rule_table(rmse: np.ndarray, err: np.ndarray, seen: np.ndarray, runs: list[Any]) -> dict[str, Any]:
    """One rule's row of the table over the repetitions (`rmse`, `err`: repeats x steps):
    mean ± SE of the cloud RMSE where a sensor sees the target (`seen`) and where none does,
    over the run, steps 0-700 and after, the estimate's error; resamples and collapses."""
    return {
        "rmse_seen": mean_se(rmse[:, seen].mean(axis=1)),
        "rmse_unseen": mean_se(rmse[:, ~seen].mean(axis=1)) if (~seen).any() else None,
        "rmse_mean": mean_se(rmse.mean(axis=1)),
        "rmse_steps_0_700": mean_se(rmse[:, : MARSH_STEPS + 1].mean(axis=1)),
        "rmse_after_700": mean_se(rmse[:, MARSH_STEPS + 1 :].mean(axis=1)),
        "estimate_error_mean": mean_se(err.mean(axis=1)),
        "resamples_per_run": float(np.mean([run.n_resamples for run in runs])),
        "collapses_per_run": float(np.mean([run.n_collapses for run in runs])),
    }


def _paired(rmse: np.ndarray, base: np.ndarray) -> dict[str, Any]:
    """A rule's paired differences against the first rule (same data, same seed; repeats x
    steps each): mean ± SE over the run and steps 0-700, and the repetitions it wins."""
    return {
        "rmse_mean_diff": mean_se(rmse.mean(axis=1) - base.mean(axis=1)),
        "rmse_steps_0_700_diff": mean_se(
            rmse[:, : MARSH_STEPS + 1].mean(axis=1) - base[:, : MARSH_STEPS + 1].mean(axis=1)
        ),
        "wins": int(np.sum(rmse.mean(axis=1) < base.mean(axis=1))),
    }


def draw_map(ax: Axes, sensors: tuple[Sensor, ...] = ()) -> None:
    """The CF map (1 white, 0.5 light grey, 0 dark grey) with the sensors' ranges."""
    grid = context_grid()
    ny, nx = grid.shape
    ax.imshow(grid.cf, cmap=CF_CMAP, vmin=0, vmax=1, origin="upper", extent=(0, nx, ny, 0), interpolation="nearest")
    for s in sensors:
        if np.isfinite(s.range_units):
            ax.add_patch(Circle((s.x, s.y), s.range_units, fill=False, ec="gold", ls=":", lw=1.5))
            ax.plot(s.x, s.y, "^", color="gold", mec="k", ms=7)
    ax.set_xlim(-3, nx + 3)
    ax.set_ylim(ny + 3, -3)
    ax.set_aspect("equal")


def _draw(path, title, rules, sensors, first, truth, curves, rmse) -> None:
    with figure(13.0, 5.2) as fig:
        ax_map, ax_rmse = fig.subplots(1, 2, width_ratios=(1, 1.25))
        draw_map(ax_map, sensors)
        z = first["measurements"]
        ax_map.plot(z[:, 1], z[:, 2], ".", color="tab:purple", ms=4, label="measurements")
        ax_map.plot(truth[:, 0], truth[:, 1], "-", color="tab:blue", lw=2, label="truth")
        for r in rules:
            est = first[r].estimate
            ax_map.plot(est[:, 0], est[:, 1], "-", color=COLORS[r], lw=1.1, label=LABELS[r])
        ax_map.set_title("repetition 1: tracks (CF: white 1, light grey 0.5, dark 0)", fontsize=9)
        ax_map.legend(fontsize=7, loc="lower right")
        steps = curves["step"].to_numpy()
        for r in rules:
            mean = rmse[r].mean(axis=0)
            se = rmse[r].std(axis=0, ddof=1) / np.sqrt(len(rmse[r])) if len(rmse[r]) > 1 else 0 * mean
            ax_rmse.plot(steps, mean, color=COLORS[r], lw=1.2, label=LABELS[r])
            ax_rmse.fill_between(steps, mean - 2 * se, mean + 2 * se, color=COLORS[r], alpha=0.2, lw=0)
        ax_rmse.axvline(MARSH_STEPS, color="0.5", ls="--", lw=0.8)
        ax_rmse.set_xlabel("time step")
        ax_rmse.set_ylabel("RMSE of the particle cloud (map units)")
        ax_rmse.set_title(f"mean over {len(rmse[rules[0]])} repetitions (band: ±2 SE)", fontsize=9)
        ax_rmse.legend(fontsize=8)
        ax_rmse.grid(True, lw=0.4, alpha=0.5)
        fig.suptitle(title, fontsize=11)
        save_png(fig, path)


def _draw_particles(path, rules, sensors, first, truth) -> None:
    """The paper's Fig. 7: the particle clouds at two steps, without and with context."""
    shown = [r for r in rules if first[r].snapshots]
    steps = sorted(first[shown[0]].snapshots)
    with figure(4.2 * len(steps) * len(shown) / 2 + 2, 4.6) as fig:
        axes = np.atleast_1d(fig.subplots(1, len(steps) * len(shown)))
        k = 0
        for step in steps:
            for r in shown:
                ax = axes[k]
                k += 1
                draw_map(ax, sensors)
                xy, _ = first[r].snapshots[step]
                ax.plot(xy[:, 0], xy[:, 1], ".", color="tab:red", ms=1.5, alpha=0.5)
                ax.plot(truth[: step + 1, 0], truth[: step + 1, 1], "-", color="navy", lw=1.5)
                ax.plot(first[r].estimate[: step + 1, 0], first[r].estimate[: step + 1, 1], "-", color="tab:green")
                ax.set_title(f"step {step}: {LABELS[r]}", fontsize=8)
        save_png(fig, path)
