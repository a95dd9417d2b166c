"""Compare the association engines (exact DP vs loopy BP) on realistic window factors.

For each clutter rate, simulate windows: s beacons around a float (planar geometry), a
particle cloud around the float, and K stored TOAs of which min(Poisson(rate), K) are
uniform clutter and the rest the earliest detected true arrivals (predicted arrival plus
N(0, sigma^2) noise). Factors come from `rafostrack.model.measurement.association_factors` with the
default configuration (clutter rate overridden). Prints, per clutter rate: mean and max
|log Z_bp - log Z_exact| over all particles, max |p_match difference|, the number of
particles where the Bethe estimate exceeds the exact log Z, BP sweeps used, and the
median wall time per call of each engine.

    python benchmarks/engines.py [--particles 1000] [--beacons 10] [--signals 4]
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from rafostrack.config import ModelConfig, load_config, with_overrides
from rafostrack.engines import Association, bp, exact
from rafostrack.model.measurement import association_factors

CLUTTER_RATES = (0.5, 1.0, 2.0, 4.0)
BOX_KM = 1000.0  # beacons uniform in a square of this side, float at its centre
CLOUD_KM = 10.0  # particle scatter (sd per axis) around the float


def simulate_window(
    rng: np.random.Generator, model: ModelConfig, particles: int, beacons: int, signals: int
) -> tuple[NDArray, NDArray]:
    """(log_match, log_unheard) of one simulated window."""
    window = model.window_s
    beacon_xy = rng.uniform(0.0, BOX_KM, (beacons, 2))
    float_xy = np.full(2, BOX_KM / 2)
    travel_max = np.hypot(BOX_KM, BOX_KM) * 1e3 / model.sound_speed_m_s
    delay = rng.uniform(0.0, max(window - travel_max, 0.0), beacons)

    def arrival(xy: NDArray) -> NDArray:
        dist_m = np.linalg.norm(xy[..., None, :] - beacon_xy, axis=-1) * 1e3
        return delay + dist_m / model.sound_speed_m_s

    mu = arrival(float_xy + rng.normal(0.0, CLOUD_KM, (particles, 2)))  # (P, s)
    n_clutter = min(int(rng.poisson(model.clutter_rate)), signals)
    heard = rng.random(beacons) < model.p_detect
    true_toa = np.sort(arrival(float_xy)[heard] + rng.normal(0.0, model.toa_sigma_s, heard.sum()))
    toa = np.sort(np.r_[true_toa[: signals - n_clutter], rng.uniform(0.0, window, n_clutter)])
    f = association_factors(
        mu,
        np.full(mu.shape, model.p_detect),
        toa,
        max_signals=signals,
        window_s=window,
        model=model,
    )
    return f.log_match, f.log_unheard


def timed(
    engine: Callable[[NDArray, NDArray], Association], args: tuple[NDArray, NDArray], repeats: int
) -> tuple[Association, list[float]]:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        result = engine(*args)
        times.append(time.perf_counter() - start)
    return result, times


def run(args: argparse.Namespace) -> None:
    rng = np.random.default_rng(args.seed)
    base = load_config()
    header = (
        f"{'clutter':>7}  {'mean|dlogZ|':>11}  {'max|dlogZ|':>10}  {'max|dp|':>8}  "
        f"{'bethe>exact':>11}  {'bp sweeps':>10}  {'exact ms':>8}  {'bp ms':>8}"
    )
    print(
        f"{args.particles} particles, {args.beacons} beacons, {args.signals} TOAs, "
        f"{args.windows} windows per rate, {args.repeats} timed calls per window"
    )
    print(header)
    print("-" * len(header))
    for rate in CLUTTER_RATES:
        model = with_overrides(base, model={"clutter_rate": rate, "max_signals": args.signals}).model
        dlog, dp, over, sweeps, t_exact, t_bp = [], [], 0, [], [], []
        for _ in range(args.windows):
            factors = simulate_window(rng, model, args.particles, args.beacons, args.signals)
            ref, times = timed(exact.associate, factors, args.repeats)
            t_exact += times
            approx, times = timed(bp.associate, factors, args.repeats)
            t_bp += times
            diff = approx.log_z - ref.log_z
            dlog.append(np.abs(diff))
            dp.append(np.abs(approx.p_match - ref.p_match).max())
            over += int(np.sum(diff > 1e-9))
            log_w = factors[0] - factors[1][:, :, None]
            sweeps.append(bp.message_passing(np.exp(log_w))[2])
        dlog_all, sweeps_all = np.concatenate(dlog), np.concatenate(sweeps)
        print(
            f"{rate:>7.1f}  {dlog_all.mean():>11.2e}  {dlog_all.max():>10.2e}  {max(dp):>8.2e}  "
            f"{over:>11d}  {f'{sweeps_all.mean():.1f}/{sweeps_all.max()}':>10}  "
            f"{1e3 * np.median(t_exact):>8.2f}  {1e3 * np.median(t_bp):>8.2f}"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--particles", type=int, default=1000)
    parser.add_argument("--beacons", type=int, default=10)
    parser.add_argument("--signals", type=int, default=4)
    parser.add_argument("--windows", type=int, default=20, help="simulated windows per clutter rate")
    parser.add_argument("--repeats", type=int, default=5, help="timed calls per window and engine")
    parser.add_argument("--seed", type=int, default=0)
    run(parser.parse_args())


if __name__ == "__main__":
    main()
