"""The ABC binary-sensor paper's experiments (section 5), redone with `rafostrack.sensors`.

One module per figure or table, each with `run(outdir, *, quick=False, seed=...) -> dict`
writing its PNG(s), the CSVs behind them and a JSON summary:

- `fig2_single`: one target, 64 sensors: RMSE over time of the exact MCMC, ABC-RW and ABC-PT;
- `fig3_5_trajectories`: ABC-RW's particles for five close targets (Fig. 3) and the bearings
  of three manoeuvring targets (Figs. 4-5);
- `table1_rmse`: RMSE at t = 10, 20, 30 s for 2-4 targets, 16 and 64 sensors, beside the
  paper's Table 1, with the ordering ABC-PT < ABC-RW < ABC-Rej checked cell by cell and
  each algorithm's compute cost.

`setting` holds the paper's setting, its Table 1 and the seeded runner; `report` writes
REPORT.md (`python -m papers.abc`).
"""
