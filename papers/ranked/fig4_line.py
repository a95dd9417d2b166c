"""Paper Fig. 4: a target moving in a straight line, 10 beacons, first 4 signals, Pd 0.7,
sigma 0.02, clutter Poisson(4): true vs estimated track, and the labelled arrival times.

    python -m papers.ranked --only fig4_line [--quick] [--out DIR]
"""

from __future__ import annotations

from .trajectory import LINE

run = LINE.run
