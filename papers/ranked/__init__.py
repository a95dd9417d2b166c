"""The ranked-signal paper's experiments (section 3, appendix A.3), redone with rafostrack.

One module per figure, each with `run(outdir, *, quick=False, seed=...) -> dict` writing its
PNG(s), the CSVs behind them and a JSON summary, and runnable alone as
`python -m papers.ranked --only <module> [--quick] [--out DIR]`:

- `fig4_line`, `fig5_spiral`: one target on a line / a spiral, its track and labelled arrivals;
- `fig6b_clutter`: MSE against the clutter parameter lambda, ranked vs the unranked baseline;
- `fig7_8_floats`: sample floats 767 and 811, ours vs the labelled filter vs the truth;
- `fig12_ambiguity`: float 759 with several seeds, where the position is not determined;
- `bp_vs_exact`: the paper's BP association against the exact sum, and their cost.

`setting` holds the paper's planar setting mapped onto the ellipsoid and the seeded runner,
`trajectory` the Figs. 4-5 experiment both use; `report` writes REPORT.md
(`python -m papers.ranked`).
"""
