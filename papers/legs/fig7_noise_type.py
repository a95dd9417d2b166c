"""Paper Fig. 7: SS error per time step for Gaussian, Uniform, Gamma and Beta measurement
noise, each of variance 25 (paper: "comparable variance to sigma^2 = 25"), T 200 s, dT 5 s.

    python -m papers.legs --only fig7_noise_type [--quick] [--out DIR]
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..common import DEFAULT_WORKERS, experiment
from .sweep import Sizes, sweep_experiment
from .target import NOISE_TYPES, Scenario

NAME = "fig7_noise_type"
BASE = Scenario(sigma2=25.0)
METHODS = ("rw_paper", "rw_ours", "rw_student", "kf", "ks")
FULL = Sizes(repeats=10, iterations=5000)
QUICK = Sizes(repeats=2, iterations=1500)
SEED = 700


@experiment(FULL, QUICK)
def run(outdir: Path, sz: Sizes, *, seed: int = SEED, workers: int = DEFAULT_WORKERS) -> dict[str, Any]:
    return sweep_experiment(outdir, NAME, "Fig. 7, noise type (variance 25)", "noise", NOISE_TYPES, METHODS, sz,
                            seed, workers, "measurement noise distribution", categorical=True, base=BASE)  # fmt: skip
