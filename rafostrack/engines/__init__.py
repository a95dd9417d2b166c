"""Inference engines for the window's association sum.

Each engine takes the factors of `rafostrack.model` (log w of shape (P, s, K), log u of
shape (P, s)) and returns an `Association`: the log of
    Z = sum over partial matchings M of prod_{(i,j) in M} w_ij prod_{i unmatched} u_i
(the window's log-likelihood less the shared clutter term) and the marginal probability
that signal j came from beacon i, per particle. Every engine accepts `marginals=False`,
a hint that only log Z is wanted (the exact engine then skips its backward pass and
returns NaN marginals).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True)
class Association:
    log_z: NDArray[np.float64]  # (P,)
    p_match: NDArray[np.float64]  # (P, s, K): P(signal j from beacon i | X)

    @property
    def p_clutter(self) -> NDArray[np.float64]:
        """(P, K): probability that each signal is clutter."""
        return np.clip(1.0 - self.p_match.sum(axis=1), 0.0, 1.0)
