"""Paper Fig. 5: a target moving in a spiral, so the set of nearest beacons keeps changing
(10 beacons, first 4 signals, Pd 0.7, sigma 0.02, clutter Poisson(4)): true vs estimated
track, and the labelled arrival times.

    python -m rafostrack.experiments.ranked.fig5_spiral OUTDIR [--quick] [--seed N]
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..common import DEFAULT_WORKERS, cli
from .trajectory import TrajectorySizes, run_trajectory

NAME = "fig5_spiral"
FULL = TrajectorySizes(days=120, particles=1000)
QUICK = TrajectorySizes(days=120, particles=400)


def run(
    outdir: Path, *, quick: bool = False, seed: int = 0, workers: int = DEFAULT_WORKERS, sizes: dict | None = None
) -> dict[str, Any]:
    """Write fig5_spiral.png and its CSVs into `outdir`; return the summary (also as JSON)."""
    return run_trajectory(
        NAME,
        "spiral",
        "Fig. 5, spiral",
        outdir,
        full=FULL,
        quick_sizes=QUICK,
        quick=quick,
        seed=seed,
        workers=workers,
        sizes=sizes,
    )


if __name__ == "__main__":  # run the importable module, so that worker processes can find its tasks
    from rafostrack.experiments.ranked import fig5_spiral as _module

    cli(_module.run, _module.__doc__)
