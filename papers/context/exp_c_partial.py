"""Paper experiment C (Figs. 6-7): partial coverage, three range-limited sensors; context at
cell entry against no context, and the particle clouds at two steps.

    python -m papers.context --only exp_c_partial [--quick] [--out DIR]
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..common import experiment
from .setting import PARTIAL_SENSORS
from .synthetic import FULL, QUICK, Sizes, run_comparison

CLAIM = (
    "with partial coverage, context gives a significant gain when the target is out of the sensors' range, "
    "especially where it turns there; the estimated track is closer to the truth and the cloud more focused"
)


@experiment(FULL, QUICK)
def run(outdir: Path, sz: Sizes, *, seed: int = 0, workers: int = 2) -> dict[str, Any]:
    """Write exp_c_partial.png, exp_c_partial_particles.png and the CSVs; return the summary."""
    title = "Experiment C (paper Figs. 6-7): three range-limited sensors, context at cell entry vs no context"
    return run_comparison(
        "exp_c_partial", title, outdir, sz, ("none", "entry"), PARTIAL_SENSORS, seed=seed, workers=workers,
        claim=CLAIM, snapshots=True,
    )  # fmt: skip
