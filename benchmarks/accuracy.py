"""Association accuracy, position RMSE and calibration of every method, filtered and smoothed.

For each clutter rate, simulate synthetic missions (ring array, `--floats` floats of
`--days` daily windows, fixed seeds), track each float with every method using the
simulation's own model settings, and print, for the filtered and the smoothed estimate,
the fraction of stored TOAs labelled correctly (beacon or clutter), the position RMSE
against the simulated truth, and the fraction of true positions inside the smoothed 95%
ellipse.

    python benchmarks/accuracy.py [--floats 3] [--days 120] [--particles 1000] [--report docs/validation.md]

`--report FILE` also writes the table into the `accuracy` section of that Markdown file
(`benchmarks/report.py`).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import pandas as pd
from report import markdown_table, write_section

from rafostrack.config import METHODS, load_config, method_overrides, with_overrides
from rafostrack.problem import FloatProblem
from rafostrack.run.method import track_record
from rafostrack.sim.evaluate import association_accuracy, inside_ellipse, position_errors_km
from rafostrack.sim.scenarios import synthetic_scenario
from rafostrack.sim.simulate import simulate_mission
from rafostrack.summaries.posterior import ELLIPSE_95_SCALE

CLUTTER_RATES = (0.5, 1.0, 2.0, 4.0)


def evaluate(clutter_rate: float, method: str, args: argparse.Namespace) -> dict[str, float]:
    """Pooled scores over the floats of one simulated mission."""
    config = with_overrides(
        load_config(),
        model={"clutter_rate": clutter_rate},
        filter={**method_overrides(method), "particles": args.particles, "seed": args.seed},
    )
    beacons, floats = synthetic_scenario(days=args.days, n_floats=args.floats, rng=args.seed)
    rng = np.random.default_rng([args.seed, int(clutter_rate * 100)])
    mission = simulate_mission(beacons, floats, config.model, rng)
    pooled: dict[str, list] = {k: [] for k in ("acc_f", "acc_s", "err_f", "err_s", "inside")}
    seconds = 0.0
    for sim in mission.floats:
        started = time.perf_counter()
        out = track_record(FloatProblem(beacons, sim.info, config), sim.record, also_filtered=True)
        seconds += time.perf_counter() - started
        n_toas = len(out.labels)
        pooled["acc_f"].append((association_accuracy(out.filtered.labels, sim.record), n_toas))
        pooled["acc_s"].append((association_accuracy(out.estimate.labels, sim.record), n_toas))
        pooled["err_f"].extend(position_errors_km(out.filtered.track, sim.truth))
        pooled["err_s"].extend(position_errors_km(out.estimate.track, sim.truth))
        pooled["inside"].extend(inside_ellipse(out.estimate.track, sim.truth, ELLIPSE_95_SCALE))

    def accuracy(pairs):
        return sum(a * n for a, n in pairs) / sum(n for _, n in pairs)

    return {
        "acc_filtered": accuracy(pooled["acc_f"]),
        "acc_smoothed": accuracy(pooled["acc_s"]),
        "rmse_filtered": float(np.sqrt(np.mean(np.square(pooled["err_f"])))),
        "rmse_smoothed": float(np.sqrt(np.mean(np.square(pooled["err_s"])))),
        "cover95": float(np.mean(pooled["inside"])),
        "seconds": seconds,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--floats", type=int, default=3)
    parser.add_argument("--days", type=int, default=120)
    parser.add_argument("--particles", type=int, default=1000)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--rates", type=float, nargs="+", default=list(CLUTTER_RATES))
    parser.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS)
    parser.add_argument("--report", type=Path, help="write the table into this Markdown file's accuracy section")
    args = parser.parse_args()

    setup = f"{args.floats} floats x {args.days} days per clutter rate, {args.particles} particles, seed {args.seed}"
    print(setup)
    head = ("clutter", "method", "acc_filt", "acc_smooth", "rmse_filt", "rmse_smooth", "cover95", "seconds")
    print(" ".join(f"{h:>11}" for h in head))
    results = {}
    for rate in args.rates:
        for method in args.methods:
            r = evaluate(rate, method, args)
            results[rate, method] = r
            print(
                f"{rate:11.1f} {method:>11} {r['acc_filtered']:11.4f} {r['acc_smoothed']:11.4f} "
                f"{r['rmse_filtered']:11.2f} {r['rmse_smoothed']:11.2f} {r['cover95']:11.3f} {r['seconds']:11.1f}",
                flush=True,
            )
    summary = ""
    if (1.0, "exact") in results and (1.0, "labeled") in results:
        exact, labeled = results[1.0, "exact"], results[1.0, "labeled"]
        ratio = exact["rmse_filtered"] / labeled["rmse_filtered"]
        summary = (
            f"\nclutter 1, exact: filtered labels {exact['acc_filtered']:.2%} correct (target >= 95%), "
            f"filtered RMSE / labelled filter's = {ratio:.2f} (target <= 1.2); "
            f"smoothed labels {exact['acc_smoothed']:.2%} (target >= 99%), "
            f"smoothed RMSE {exact['rmse_smoothed']:.2f} km vs filtered {exact['rmse_filtered']:.2f} km "
            f"(labelled filter {labeled['rmse_filtered']:.2f} km), "
            f"95% ellipse coverage {exact['cover95']:.1%} (target 90-98%)"
        )
        print(f"\n{summary}")
    if args.report:
        write_section(args.report, "accuracy", _report(setup, results, summary))


def _report(setup: str, results: dict[tuple[float, str], dict[str, float]], summary: str) -> str:
    """The accuracy section: the setting, the table per clutter rate and method, and the clutter-1 summary."""
    table = pd.DataFrame([{"clutter": rate, "method": method, **r} for (rate, method), r in results.items()])
    formats = {
        "clutter": lambda x: f"{x:g}",
        **{c: (lambda x: f"{x:.2%}") for c in ("acc_filtered", "acc_smoothed")},
        **{c: (lambda x: f"{x:.2f}") for c in ("rmse_filtered", "rmse_smoothed")},
        "cover95": lambda x: f"{x:.1%}",
        "seconds": lambda x: f"{x:.1f}",
    }
    text = (
        "Synthetic missions (ring array), tracked by every method with the simulation's own model settings: "
        "labels right (`acc_*`, beacon or clutter), position RMSE (km) and the smoothed 95%-ellipse coverage, "
        f"filtered and smoothed.\n\n{setup}.\n\n{markdown_table(table, formats)}"
    )
    return text + (f"\n\n{summary}." if summary else "")


if __name__ == "__main__":
    main()
