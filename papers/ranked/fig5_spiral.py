"""Paper Fig. 5: a target moving in a spiral, so the set of nearest beacons keeps changing
(10 beacons, first 4 signals, Pd 0.7, sigma 0.02, clutter Poisson(4)): true vs estimated
track, and the labelled arrival times.

    python -m papers.ranked --only fig5_spiral [--quick] [--out DIR]
"""

from __future__ import annotations

from .trajectory import SPIRAL

run = SPIRAL.run
