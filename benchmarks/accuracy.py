"""Association accuracy and position RMSE of every method on simulated missions.

For each clutter rate, simulate synthetic missions (ring array, `--floats` floats of
`--days` daily windows, fixed seeds), track each float with every method using the
simulation's own model settings, and print the fraction of stored TOAs labelled correctly
(beacon or clutter) and the position RMSE against the simulated truth.

    python benchmarks/accuracy.py [--floats 3] [--days 120] [--particles 1000]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from rafostrack.config import METHODS, load_config, with_overrides
from rafostrack.evaluate import association_accuracy, position_errors_km
from rafostrack.filter import ParticleFilter, float_rng
from rafostrack.simulate import simulate_mission, synthetic_scenario

CLUTTER_RATES = (0.5, 1.0, 2.0, 4.0)


def evaluate(clutter_rate: float, method: str, args: argparse.Namespace) -> dict[str, float]:
    """Pooled accuracy and RMSE over the floats of one simulated mission."""
    config = with_overrides(
        load_config(),
        model={"clutter_rate": clutter_rate},
        filter={"method": method, "particles": args.particles, "seed": args.seed},
    )
    beacons, floats = synthetic_scenario(days=args.days, n_floats=args.floats, rng=args.seed)
    mission = simulate_mission(
        beacons, floats, config.model, np.random.default_rng([args.seed, int(clutter_rate * 100)])
    )
    correct, total, sq_err, n_pos, elapsed = 0, 0, 0.0, 0, 0.0
    for sim in mission.floats:
        started = time.perf_counter()
        out = ParticleFilter(beacons, sim.info, config).run(sim.record, float_rng(args.seed, sim.info.float_id))
        elapsed += time.perf_counter() - started
        n_toas = len(out.labels)
        correct += association_accuracy(out.labels, sim.record) * n_toas
        total += n_toas
        err = position_errors_km(out.track, sim.truth)
        sq_err += float(np.sum(err**2))
        n_pos += len(err)
    return {
        "accuracy": correct / total,
        "rmse_km": np.sqrt(sq_err / n_pos),
        "seconds": elapsed,
        "toas": total,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--floats", type=int, default=3)
    parser.add_argument("--days", type=int, default=120)
    parser.add_argument("--particles", type=int, default=1000)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--rates", type=float, nargs="+", default=list(CLUTTER_RATES))
    args = parser.parse_args()

    print(f"{args.floats} floats x {args.days} days per clutter rate, {args.particles} particles, seed {args.seed}")
    print(f"{'clutter':>8} {'method':>9} {'accuracy':>9} {'rmse_km':>8} {'seconds':>8}")
    results = {}
    for rate in args.rates:
        for method in METHODS:
            r = evaluate(rate, method, args)
            results[rate, method] = r
            print(
                f"{rate:8.1f} {method:>9} {r['accuracy']:9.4f} {r['rmse_km']:8.2f} {r['seconds']:8.1f}",
                flush=True,
            )
    if 1.0 in args.rates:
        exact, labeled = results[1.0, "exact"], results[1.0, "labeled"]
        ratio = exact["rmse_km"] / labeled["rmse_km"]
        print(
            f"\nclutter 1: exact labels {exact['accuracy']:.1%} correct (target >= 95%): "
            f"{'met' if exact['accuracy'] >= 0.95 else 'NOT met'}; "
            f"RMSE exact / labeled = {ratio:.2f} (target <= 1.2): {'met' if ratio <= 1.2 else 'NOT met'}"
        )


if __name__ == "__main__":
    main()
