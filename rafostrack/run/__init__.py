"""One float, in the order it runs: `one_float.track_float` (files in, an output directory
out) -> `run.method.track_record` (robust pass, calibration, calibrated passes) ->
`one_pass.Tracker.track` (filter, smoother, summaries of one pass)."""
