"""The measurement model: ranges on the ellipsoid (`geodesy`), predicted arrivals, the TOA
error density and the association factor tables of a window (`measurement`), and their
compiled kernels (`kernels`)."""
