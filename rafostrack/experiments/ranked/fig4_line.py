"""Paper Fig. 4: a target moving in a straight line, 10 beacons, first 4 signals, Pd 0.7,
sigma 0.02, clutter Poisson(4): true vs estimated track, and the labelled arrival times.

    python -m rafostrack.experiments.ranked.fig4_line OUTDIR [--quick] [--seed N]
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..common import DEFAULT_WORKERS, cli
from .trajectory import TrajectorySizes, run_trajectory

NAME = "fig4_line"
FULL = TrajectorySizes(days=60, particles=1000)
QUICK = TrajectorySizes(days=60, particles=400)


def run(
    outdir: Path, *, quick: bool = False, seed: int = 0, workers: int = DEFAULT_WORKERS, sizes: dict | None = None
) -> dict[str, Any]:
    """Write fig4_line.png and its CSVs into `outdir`; return the summary (also as JSON)."""
    return run_trajectory(
        NAME,
        "line",
        "Fig. 4, straight line",
        outdir,
        full=FULL,
        quick_sizes=QUICK,
        quick=quick,
        seed=seed,
        workers=workers,
        sizes=sizes,
    )


if __name__ == "__main__":  # run the importable module, so that worker processes can find its tasks
    from rafostrack.experiments.ranked import fig4_line as _module

    cli(_module.run, _module.__doc__)
