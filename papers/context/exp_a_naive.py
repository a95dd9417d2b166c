"""Paper experiment A (Fig. 4): context at every step (the naive rule) against no context,
one sensor seeing the whole map.

    python -m papers.context --only exp_a_naive [--quick] [--out DIR]
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..common import experiment
from .setting import FULL_SENSORS
from .synthetic import FULL, QUICK, Sizes, run_comparison

CLAIM = (
    "context compensates the overshoots at sharp turns and lowers the RMSE overall, but the naive rule makes "
    "severe errors in the south-western area of CF 0.5, visible in the RMSE between steps 0 and 700"
)


@experiment(FULL, QUICK)
def run(outdir: Path, sz: Sizes, *, seed: int = 0, workers: int = 2) -> dict[str, Any]:
    """Write exp_a_naive.png and its CSVs; return the summary."""
    title = "Experiment A (paper Fig. 4): context at every step (naive) vs no context, full coverage"
    return run_comparison(
        "exp_a_naive", title, outdir, sz, ("none", "naive"), FULL_SENSORS, seed=seed, workers=workers, claim=CLAIM
    )
