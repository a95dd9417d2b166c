"""The particle filter (`filter`) and what it is made of: log-weights and resampling
schemes (`resampling`), the cloud's modes (`modes`), lost-track detection and re-seeding
(`recovery`), and the guided proposal (`guided`)."""
