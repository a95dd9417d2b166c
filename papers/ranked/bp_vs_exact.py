"""BP vs exact: how far the paper's loopy-BP association (Bethe estimate) is from the exact
sum, across clutter levels, and what each costs per call.

Windows are simulated in the paper setting along Fig. 4's straight line (the package's
generative model); for each window a particle cloud is drawn around the true position
(sd `CLOUD_KM` per axis: a filter cloud a few times wider than its ~10 km posterior, so
that particles off the mode are included). The window's factors come from
`rafostrack.model.measurement.association_factors`; both engines (`rafostrack.engines.exact` and
`.bp`, default tolerance) run on the same factors. Reported per clutter level: the
log-likelihood error |log Z_bp - log Z_exact| per particle (median, 95th percentile, max),
the error in the particle filter's normalised weights (total variation distance per
window), the association-marginal error max |p_bp - p_exact| per window, BP sweeps, and the
median wall time per call (all particles) of each engine.

    python -m papers.ranked --only bp_vs_exact [--quick] [--out DIR]
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from rafostrack.engines import bp, exact
from rafostrack.filtering.resampling import normalise_log_weights
from rafostrack.model import measurement as m
from rafostrack.motion import RandomWalk
from rafostrack.plots import save_png

from ..common import DEFAULT_WORKERS, experiment, figure, pmap, save_csv
from .setting import CLUTTER_LEVELS, line_record

NAME = "bp_vs_exact"


@dataclass(frozen=True)
class Sizes:
    particles: int
    windows: int  # windows per clutter level (the line's first `windows` days)
    lambdas: tuple[float, ...] = CLUTTER_LEVELS


FULL = Sizes(particles=1000, windows=60)
QUICK = Sizes(particles=300, windows=15)
SEED = 7  # the default seed of the published run
CLOUD_KM = 30.0  # sd per axis of the particle cloud about the true position


def _level(task: tuple[float, int, int, int]) -> list[dict[str, Any]]:
    """Every window of one clutter level: both engines on the same factors."""
    lam, seed, particles, windows = task
    scenario, config, record = line_record(windows, lam, particles, seed, seed, lam)
    model = config.model
    rng = np.random.default_rng([seed, int(lam * 1000), 1])
    info, beacons = scenario.info, scenario.beacons
    rows = []
    for k, window in enumerate(record.windows):
        if window.n_signals == 0:
            continue
        lat0, lon0 = scenario.truth["lat"].iloc[k + 1], scenario.truth["lon"].iloc[k + 1]
        cloud = RandomWalk(CLOUD_KM).initial(lat0, lon0, CLOUD_KM, particles, rng)
        lat, lon = cloud.lat, cloud.lon
        wb = m.window_beacons(beacons, info, window.time)
        ranges = m.beacon_ranges_m(lat, lon, wb)
        f = m.association_factors(
            m.predicted_toa_s(ranges, wb, model),
            m.detection_prob(ranges, wb, model),
            window.toa_s,
            max_signals=info.max_signals,
            window_s=info.window_s,
            model=model,
        )
        t0 = time.perf_counter()
        ref = exact.associate(f.log_match, f.log_unheard)
        t1 = time.perf_counter()
        approx = bp.associate(
            f.log_match, f.log_unheard, tolerance=config.bp.tolerance, max_iterations=config.bp.max_iterations
        )
        t2 = time.perf_counter()
        sweeps = bp.message_passing(
            np.exp(f.log_match - f.log_unheard[:, :, None]),
            tolerance=config.bp.tolerance,
            max_iterations=config.bp.max_iterations,
        )[2]
        dlog = approx.log_z - ref.log_z
        w_ref, _ = normalise_log_weights(ref.log_z)
        w_bp, _ = normalise_log_weights(approx.log_z)
        dp = np.abs(approx.p_match - ref.p_match).reshape(particles, -1).max(axis=1)
        rows.append(
            {
                "lambda": lam,
                "window": k + 1,
                "signals": window.n_signals,
                "true_signals": sum(b is not None for b in window.beacon_id or ()),
                "dlogz_median": float(np.median(np.abs(dlog))),
                "dlogz_p95": float(np.quantile(np.abs(dlog), 0.95)),
                "dlogz_max": float(np.abs(dlog).max()),
                "bethe_above_exact": int(np.sum(dlog > 1e-9)),
                "weights_tv": float(0.5 * np.abs(w_bp - w_ref).sum()),
                "dp_max": float(dp.max()),
                "dp_weighted_mean": float(w_ref @ dp),
                "bp_sweeps_mean": float(sweeps.mean()),
                "bp_sweeps_max": int(sweeps.max()),
                "exact_ms": 1e3 * (t1 - t0),
                "bp_ms": 1e3 * (t2 - t1),
            }
        )
    return rows


@experiment(FULL, QUICK)
def run(outdir: Path, sz: Sizes, *, seed: int = SEED, workers: int = DEFAULT_WORKERS) -> dict[str, Any]:
    """Write bp_vs_exact.png, its CSVs and summary into `outdir`."""
    tasks = [(float(lam), seed, sz.particles, sz.windows) for lam in sz.lambdas]
    raw = pd.DataFrame([row for rows in pmap(_level, tasks, workers) for row in rows])
    agg = (
        raw.groupby("lambda")
        .agg(
            windows=("window", "size"),
            dlogz_median=("dlogz_median", "median"),
            dlogz_p95=("dlogz_p95", "median"),
            dlogz_max=("dlogz_max", "max"),
            bethe_above_exact=("bethe_above_exact", "sum"),
            weights_tv_median=("weights_tv", "median"),
            weights_tv_max=("weights_tv", "max"),
            dp_max_median=("dp_max", "median"),
            dp_max=("dp_max", "max"),
            dp_weighted_mean=("dp_weighted_mean", "mean"),
            bp_sweeps_mean=("bp_sweeps_mean", "mean"),
            bp_sweeps_max=("bp_sweeps_max", "max"),
            exact_ms=("exact_ms", "median"),
            bp_ms=("bp_ms", "median"),
        )
        .reset_index()
    )
    files = [f"{NAME}.png", f"{NAME}.csv", f"{NAME}_windows.csv"]
    save_csv(agg, outdir / files[1])
    save_csv(raw, outdir / files[2])
    _draw(outdir / files[0], raw, agg, sz)
    summary = {
        "name": NAME,
        "title": "BP vs exact association",
        "files": files,
        "seed": seed,
        "particles": sz.particles,
        "windows": sz.windows,
        "cloud_km": CLOUD_KM,
        "table": agg.to_dict(orient="records"),
    }
    return summary


def _draw(path: Path, raw: pd.DataFrame, agg: pd.DataFrame, sz: Sizes) -> None:
    lams = agg["lambda"].to_numpy()
    with figure(14.0, 4.8) as fig:
        ax_z, ax_p, ax_t = fig.subplots(1, 3)
        for ax, cols, title, ylabel in (
            (
                ax_z,
                (
                    ("dlogz_median", "median over particles"),
                    ("dlogz_p95", "95th percentile"),
                    ("dlogz_max", "max over particles"),
                ),
                "(a) log-likelihood error",
                "|log Z_BP − log Z_exact|",
            ),
            (
                ax_p,
                (("dp_weighted_mean", "posterior-weighted mean"), ("dp_max", "max over particles")),
                "(b) association-marginal error",
                "|p_BP − p_exact| (max over i, j); weights TV",
            ),
        ):
            for (col, label), color in zip(cols, ("tab:blue", "tab:orange", "tab:red"), strict=False):
                q = raw.groupby("lambda")[col]
                lo, mid, hi = q.quantile(0.1), q.median(), q.quantile(0.9)
                ax.plot(lams, mid.to_numpy(), "o-", color=color, label=f"{label} (median over windows)")
                ax.fill_between(lams, lo.to_numpy(), hi.to_numpy(), color=color, alpha=0.15, lw=0)
            ax.set_yscale("log")
            ax.set_title(title, fontsize=10)
            ax.set_ylabel(ylabel)
            ax.legend(fontsize=7.5, loc="lower right", title="band: 10-90% of windows", title_fontsize=7.5)
        ax_z.set_ylim(bottom=1e-5)
        ax_p.set_ylim(bottom=1e-4)
        ax_p.plot(
            lams, agg["weights_tv_median"], "s--", color="tab:green", label="filter weights: TV distance (median)"
        )
        ax_p.legend(fontsize=7.5, loc="lower right", title="band: 10-90% of windows", title_fontsize=7.5)
        ax_t.plot(lams, agg["exact_ms"], "o-", color="tab:blue", label="exact (subset DP)")
        ax_t.plot(lams, agg["bp_ms"], "s-", color="tab:purple", label="loopy BP (Bethe)")
        ax_t.set_ylabel(f"ms per call ({sz.particles} particles, median)")
        ax_t.set_title("(c) time per call", fontsize=10)
        ax_t.set_ylim(bottom=0)
        ax_t.legend(fontsize=8)
        for ax in (ax_z, ax_p, ax_t):
            ax.set_xscale("log", base=2)
            ax.set_xticks(lams, [f"{x:g}" for x in lams])
            ax.set_xlabel("clutter parameter λ")
            ax.grid(True, which="both", lw=0.4, alpha=0.5)
        fig.suptitle(
            f"BP vs exact on paper-setting windows (10 beacons, first 4 signals; {sz.windows} windows per λ, "
            f"{sz.particles} particles within {CLOUD_KM:g} km of the truth)",
            fontsize=11,
        )
        save_png(fig, path)
