"""The context-driven tracking paper's experiments (section III), redone with rafostrack.

One module per figure, each with `run(outdir, *, quick=False, seed=...) -> dict` writing its
PNG(s), the CSVs behind them and a JSON summary:

- `exp_a_naive` (Fig. 4): the naive rule (CF at every step) against no context;
- `exp_b_entry` (Fig. 5): the paper's cell-entry rule against no context;
- `exp_c_partial` (Figs. 6-7): three range-limited sensors, cell entry against no context;
- `floats_ridge`: the method on a RAFOS float drifting along a ridge, with a gap in its
  record, tracked by rafostrack with and without the bathymetry constraint.

`setting` holds the synthetic map and its context network, `synthetic` the runner the three
planar experiments share; `report` writes REPORT.md (`python -m papers.context`).
"""
