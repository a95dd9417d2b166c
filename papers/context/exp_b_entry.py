"""Paper experiment B (Fig. 5): context at cell entry (the paper's rule) against no context,
one sensor seeing the whole map.

    python -m papers.context --only exp_b_entry [--quick] [--out DIR]
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..common import experiment
from .setting import FULL_SENSORS
from .synthetic import FULL, QUICK, Sizes, run_comparison

CLAIM = (
    "with the CF used only when a particle enters a new area, tracking in the area of lower CF is significantly "
    "more accurate than with the naive rule, elsewhere as good, and the RMSE is lower than without context"
)


@experiment(FULL, QUICK)
def run(outdir: Path, sz: Sizes, *, seed: int = 0, workers: int = 2) -> dict[str, Any]:
    """Write exp_b_entry.png and its CSVs; return the summary."""
    title = "Experiment B (paper Fig. 5): context at cell entry vs no context (and the naive rule), full coverage"
    return run_comparison(
        "exp_b_entry", title, outdir, sz, ("none", "entry", "naive"), FULL_SENSORS, seed=seed, workers=workers,
        claim=CLAIM,
    )  # fmt: skip
