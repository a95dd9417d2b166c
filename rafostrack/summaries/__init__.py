"""From weighted clouds to tables: mean, covariance, ellipses and the two-mode split
(`posterior`), and the track, labels and modes tables of a pass (`estimates`)."""
