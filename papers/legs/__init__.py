"""The random-walk leg paper's experiments (Thomas 2009, Figs. 5-8 and Table 2), redone.

One module per figure or table, each with `run(outdir, *, quick=False, seed=...) -> dict`
writing its PNG, the CSVs behind it and a JSON summary:

- `fig5_noise`, `fig6_interval`, `fig7_noise_type`: one factor varied (`sweep`);
- `fig8_iterations`: error and run time against the MCMC iterations;
- `table2_overall`: 200 random scenarios, win rate with its 95% interval.

`target` is what replaces the paper's tank simulation, `methods` the methods compared (the
paper's RW sampler, ours, the EM Kalman filter and smoother); `report` writes REPORT.md
(`python -m papers.legs`).
"""
