"""Smoothers over the filter's stored clouds: FFBSm on quantile points (`ffbsm`, compiled
pairwise sums in `ffbsm_kernel`) and, with an end fix, the two-filter smoother
(`two_filter`)."""
