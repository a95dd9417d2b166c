"""REPORT.md of the random-walk leg paper's experiments, from their JSON summaries.

python -m papers.legs [--quick] [--out figures/legs] [--only NAME ...] [--report-only]
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ..runner import read_summaries, write_report
from .methods import LABELS

TITLE = "the random-walk leg paper (Figs. 5-8, Table 2)"
EXPERIMENTS = ("fig5_noise", "fig6_interval", "fig7_noise_type", "fig8_iterations", "table2_overall")

COLUMNS = ("rw_paper", "kf", "rw_ours", "ks")  # Table 2's columns of ours
CLAIMS = {
    "fig5_noise": "'although the trends of the two methods are similar, our method is slightly more robust' (Fig. 5)",
    "fig6_interval": "'our method is much more capable of handling sparse reports than Kalman filter' (Fig. 6)",
    "fig7_noise_type": "'in each distribution type, our method achieves a lower error than the Kalman filter' (Fig. 7)",
}


def _pm(mean: float, se: float, digits: int = 1) -> str:
    if not math.isfinite(mean):
        return "–"
    return f"{mean:.{digits}f} ± {se:.{digits}f}" if math.isfinite(se) else f"{mean:.{digits}f}"


def section_sweep(s: dict[str, Any]) -> list[str]:
    methods = s["methods"]
    lines = [f"![{s['name']}]({s['files'][0]})", "", f"Paper: {CLAIMS.get(s['name'], '')}.", "",
             f"Mean SS error per time step ± 1 SE over {s['repeats']} paired repeats ({s['iterations']} MCMC "
             f"iterations; other settings {s['defaults']}). Last columns: paired difference RW − Kalman filter "
             "(negative: RW better) and the repeats RW won.", "",
             "| " + s["factor"] + " | " + " | ".join(LABELS[m] for m in methods)
             + " | paper RW − KF (wins) | ours − KF (wins) |",
             "|---|" + "---:|" * (len(methods) + 2)]  # fmt: skip
    for r in s["table"]:
        cells = [_pm(r[f"{m}_mean"], r[f"{m}_se"]) for m in methods]
        diffs = [
            f"{_pm(r[f'{m}_minus_kf'], r[f'{m}_minus_kf_se'])} ({r[f'{m}_wins']}/{r['repeats']})"
            if f"{m}_minus_kf" in r
            else "–"
            for m in ("rw_paper", "rw_ours")
        ]
        lines.append(f"| {r['level']} | " + " | ".join(cells + diffs) + " |")
    return lines


def section_fig8(s: dict[str, Any]) -> list[str]:
    lines = [f"![{s['name']}]({s['files'][0]})", "",
             "Paper: 'SS decreases as N increases, but started to level out after about 15,000 simulations ... "
             "execution time is also increased linearly as N increases' (Fig. 8; 5,000 ≤ N ≤ 10,000 advised).", "",
             f"Defaults (T 200 s, σ² 5, ΔT 5 s, Gaussian), {s['repeats']} paired repeats; Kalman filter on the same "
             f"runs: {_pm(s['kf_mean'], s['kf_se'])}.", "",
             "| N | " + " | ".join(f"{LABELS[m]}: SS/time | s per fit" for m in ("rw_paper", "rw_ours")) + " |",
             "|---:|---:|---:|---:|---:|"]  # fmt: skip
    for r in s["table"]:
        cells = []
        for m in ("rw_paper", "rw_ours"):
            cells += [_pm(r[f"{m}_mean"], r[f"{m}_se"]), f"{r[f'{m}_seconds']:.2f}"]
        lines.append(f"| {r['iterations']} | " + " | ".join(cells) + " |")
    return lines


def section_table2(s: dict[str, Any]) -> list[str]:
    m, paper = s["methods"], s["paper"]
    pair = {(p["a"], p["b"]): p for p in s["pairs"]}
    pk, ok = pair[("rw_paper", "kf")], pair[("rw_ours", "kf")]

    def rate(p: dict[str, Any]) -> str:
        lo, hi = p["a_win_rate_ci95"]
        return f"{100 * p['a_win_rate']:.0f}% [{100 * lo:.0f}, {100 * hi:.0f}]"

    def lose(p: dict[str, Any]) -> str:
        lo, hi = p["a_win_rate_ci95"]
        return f"{100 * (1 - p['a_win_rate']):.0f}% [{100 * (1 - hi):.0f}, {100 * (1 - lo):.0f}]"

    lines = [f"![{s['name']}]({s['files'][0]})", "",
             f"{s['scenarios']} scenarios (σ² ~ U(0, 1600), T ~ U(50, 500) s, ΔT ~ U(1, 20) s, noise type uniform over "
             f"the four), {s['iterations']} MCMC iterations. Means ± 95% half-widths (1.96 SE); win rates with 95% "
             "Wilson intervals; average win amount = mean decrease in SS / time over the scenarios won (± 1 SE). "
             "Our absolute errors are about three times the paper's: the scale is set by the targets' speeds and turns "
             "and the tank tracks are unknown (ours follow the paper's text, section 4.1); the win rates compare "
             "methods on the same runs and do not depend on the scale.", "",
             "| | paper: RW | paper: KF | ours: RW (paper's sampler) | ours: KF (EM) | ours: RW (ours) "
             "| ours: KS (EM) |",
             "|---|---:|---:|---:|---:|---:|---:|",
             f"| SS error | {paper['rw_paper']['ss']} | {paper['kf']['ss']} | "
             + " | ".join(f"{m[k]['ss']:.0f} ± {m[k]['ss_ci95']:.0f}" for k in COLUMNS) + " |",
             f"| SS error / time | {paper['rw_paper']['ss_per_time']} | {paper['kf']['ss_per_time']} | "
             + " | ".join(f"{m[k]['ss_per_time']:.1f} ± {m[k]['ss_per_time_ci95']:.1f}" for k in COLUMNS) + " |",
             "| median SS error / time | – | – | "
             + " | ".join(f"{m[k]['median_ss_per_time']:.1f}" for k in COLUMNS) + " |",
             f"| win % vs KF | 76% | 24% | {rate(pk)} | {lose(pk)} (vs paper's RW) | {rate(ok)} | – |",
             f"| avg. win amount vs KF | 4.6 | 0.5 | {_pm(pk['a_avg_win'], pk['a_avg_win_se'])} | "
             f"{_pm(pk['b_avg_win'], pk['b_avg_win_se'])} (vs paper's RW) | "
             f"{_pm(ok['a_avg_win'], ok['a_avg_win_se'])} | – |",
             "| seconds per fit | – | – | " + " | ".join(f"{m[k]['seconds']:.2f}" for k in COLUMNS) + " |",
             "", "Other pairs (paired on SS / time):", "",
             "| a vs b | a wins | 95% interval | mean (b − a) ± SE |", "|---|---:|---:|---:|"]  # fmt: skip
    for p in s["pairs"]:
        lo, hi = p["a_win_rate_ci95"]
        lines.append(f"| {p['a']} vs {p['b']} | {p['a_wins']}/{p['n']} | [{100 * lo:.0f}%, {100 * hi:.0f}%] | "
                     f"{_pm(p['mean_b_minus_a'], p['mean_b_minus_a_se'], 2)} |")  # fmt: skip
    lines += ["", "Mean SS error / time by noise type:", "",
              "| noise | n | " + " | ".join(LABELS[k] for k in ("rw_paper", "rw_ours", "kf", "ks")) + " |",
              "|---|---:|---:|---:|---:|---:|"]  # fmt: skip
    for noise, row in s["by_noise"].items():
        lines.append(
            f"| {noise} | {row['n']} | "
            + " | ".join(f"{row[k]:.1f}" for k in ("rw_paper", "rw_ours", "kf", "ks"))
            + " |"
        )
    return lines


SECTIONS: dict[str, tuple[str, Callable[[dict[str, Any]], list[str]]]] = {
    "table2_overall": ("Table 2 — 200 random scenarios", section_table2),
    "fig5_noise": ("Fig. 5 — noise variance", section_sweep),
    "fig6_interval": ("Fig. 6 — measurement interval", section_sweep),
    "fig7_noise_type": ("Fig. 7 — noise type", section_sweep),
    "fig8_iterations": ("Fig. 8 — iterations: error and run time", section_fig8),
}
ORDER = ("table2_overall", "fig5_noise", "fig6_interval", "fig7_noise_type", "fig8_iterations")

SETUP = [
    "**What replaces the paper's tank simulation.** The paper's truth tracks came from a military tank simulation "
    "(the Timeline Analysis Model) that is not available. Ours (`papers/legs/target.py`) follows the paper's "
    "description of those tracks without being its model: legs of U(5, 40) s, each turning by U(−π/4, π/4) from the "
    "last, speeds U(8, 17) units/s, turned at a finite rate (0.6 rad/s) and accelerated at 3 units/s², integrated "
    "every 0.05 s, so corners are rounded and speeds ramp: the RW model is only approximately right, as it would be "
    "for a tank. Measurements every ΔT s from 0 to T; noise per axis of variance σ², centred: Gaussian, "
    "Uniform(±√3σ), Gamma = exponential(scale σ) − σ (skewed), Beta(½, ½) scaled (U-shaped). The paper does not say "
    "whether its Gamma and Beta noise were centred; uncentred noise would bias every method alike.",
    "",
    "**The methods.** *RW, paper*: the paper's system as written (`rafostrack.legs`): the prior of section 4.1, "
    "θ₀ from the data (k ∈ {5, …, 50}, section 4.3), fixed K, Metropolis-Hastings with the paper's proposals "
    "(speed N(·, 3), heading N(·, 0.025) random walks on 1-3 legs, durations redrawn from U(1, 40)), a quarter "
    "burn-in, the estimate the trajectory of the chain's mean parameters (section 5, step 6). Its score (summed "
    "distance) becomes a likelihood the way its MCMC toolbox (Laine's `mcmcrun`) uses a sum-of-squares function, "
    "exp(−S / (2 σ²_toolbox)); we take the toolbox's default σ²_toolbox = 1 (the paper's 'covariance matrix' of "
    "step 4 read as the proposal covariance). Fig. 5 also shows the other reading, σ²_toolbox = the noise variance: "
    "the posterior is then nearly flat at large noise and the chain's mean drifts. *RW, ours*: the same prior; θ₀ "
    "over every k in 1..50 (the paper's k ∈ {5, 10, …, 50} misaligns the legs with the measurements when T/ΔT is "
    "not a multiple of 5, e.g. ΔT = 15 s: 13 intervals, and the paper's sampler does not recover in 5,000 "
    "iterations, Fig. 6); "
    "a Gaussian likelihood with the given σ (Student-t in Fig. 7 too), our local moves (a knot, a change time, the "
    "start) beside the paper's, reversible jump over K (split/merge), the pointwise posterior mean as the estimate. "
    "*KF / KS*: a constant-velocity Kalman filter / RTS smoother whose noise levels (acceleration intensity q, the "
    "2×2 measurement covariance, the initial state) are learnt by EM (`rafostrack.legs.kalman`; the paper used "
    "Murphy's toolbox, which fits every matrix by EM; we keep the constant-velocity structure). The filter is the "
    "paper's baseline: it predicts between measurements; the smoother is the stronger baseline it did not run.",
    "",
    "**Where ours differs from the paper.** Truth from our simulator, not the tank simulation; the samplers are given "
    "max(σ², 1) (σ² = 0 would make the likelihood singular); the start is fixed at the first measurement (the paper's "
    "θ has 1 + 3K numbers, so no start); the last leg runs to the end of the data (its duration is implied, the "
    "paper's τ_K beyond the data is not identified); θ₀ skips guesses k whose equal durations the prior forbids; the "
    "error SS = Σ_{t=1..T} |z_t − x_t| at whole seconds, as the paper defines it.",
]


def build_report(
    outdir: Path, summaries: dict[str, dict[str, Any]] | None = None, total_s: float | None = None
) -> Path:
    """Write `outdir/REPORT.md` from the summaries (read from `outdir` when not given)."""
    summaries = summaries if summaries is not None else read_summaries(Path(outdir), EXPERIMENTS)
    intro = [
        "Paper: S. W. Thomas, *Learning to track a random-walk target motion using Markov chain Monte Carlo* "
        "(`leg-mcmc-random-walk.txt`). Its figures give no numbers; Table 2 does, and is set beside ours.",
        "",
        *SETUP,
    ]
    return write_report(
        outdir,
        summaries,
        total_s,
        paper="random-walk leg paper's",
        package="legs",
        quick_sizes="few repeats and iterations",
        intro=intro,
        sections=[(SECTIONS[n][0], SECTIONS[n][1](summaries[n])) for n in ORDER if n in summaries],
    )
