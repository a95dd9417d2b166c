"""Paper Fig. 6: SS error per time step against the measurement interval dT (s), the other
settings at the paper's defaults (T 200 s, sigma^2 5, Gaussian).

    python -m papers.legs --only fig6_interval [--quick] [--out DIR]
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..common import DEFAULT_WORKERS, experiment
from .sweep import Sizes, sweep_experiment

NAME = "fig6_interval"
LEVELS = (1.0, 5.0, 10.0, 15.0, 20.0)
METHODS = ("rw_paper", "rw_ours", "kf", "ks")
FULL = Sizes(repeats=10, iterations=5000)
QUICK = Sizes(repeats=2, iterations=1500)
SEED = 600


@experiment(FULL, QUICK)
def run(outdir: Path, sz: Sizes, *, seed: int = SEED, workers: int = DEFAULT_WORKERS) -> dict[str, Any]:
    return sweep_experiment(outdir, NAME, "Fig. 6, measurement interval", "interval_s", LEVELS, METHODS, sz, seed,
                            workers, "measurement interval ΔT (s)")  # fmt: skip
