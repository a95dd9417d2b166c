"""Leg-based trajectories by MCMC: the random-walk leg paper (Thomas 2009), reproduced, and
leg fits for floats.

One module per concept: `model` (legs as knots, the prior), `trajectory` (positions and
velocities at any times), `scores` (the paper's summed-distance score and our
likelihoods), `theta0` (the data-driven start), `sampler` (Metropolis-Hastings with the
paper's and our moves), `rjmcmc` (split/merge over the number of legs), `summaries`
(posterior mean, MAP, credible bands, leg table), `kalman` (the EM-learnt Kalman
baseline), `plane` and `evidence` (a float's windows as a likelihood of positions) and
`floats` (`rafostrack legs FLOAT.csv`).
"""

from .model import LegPrior, Legs, log_prior, sample_prior
from .sampler import Chain, SamplerConfig, run_chain
from .scores import GaussianLikelihood, Measurements, PaperScoreLikelihood, StudentLikelihood, paper_score
from .theta0 import data_driven_start

__all__ = [
    "Chain",
    "GaussianLikelihood",
    "LegPrior",
    "Legs",
    "Measurements",
    "PaperScoreLikelihood",
    "SamplerConfig",
    "StudentLikelihood",
    "data_driven_start",
    "log_prior",
    "paper_score",
    "run_chain",
    "sample_prior",
]
