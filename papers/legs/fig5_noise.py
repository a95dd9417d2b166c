"""Paper Fig. 5: SS error per time step against the measurement noise variance (0 to 1600
in four steps), the other settings at the paper's defaults (T 200 s, dT 5 s, Gaussian).

    python -m papers.legs --only fig5_noise [--quick] [--out DIR]
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..common import DEFAULT_WORKERS, experiment
from .sweep import Sizes, sweep_experiment

NAME = "fig5_noise"
LEVELS = (0.0, 400.0, 800.0, 1200.0, 1600.0)
METHODS = ("rw_paper", "rw_paper_var", "rw_ours", "kf", "ks")
FULL = Sizes(repeats=10, iterations=5000)
QUICK = Sizes(repeats=2, iterations=1500)
SEED = 500


@experiment(FULL, QUICK)
def run(outdir: Path, sz: Sizes, *, seed: int = SEED, workers: int = DEFAULT_WORKERS) -> dict[str, Any]:
    return sweep_experiment(outdir, NAME, "Fig. 5, noise variance", "sigma2", LEVELS, METHODS, sz, seed, workers,
                            "measurement noise variance σ² (units²)")  # fmt: skip
