"""What every output column means: units, a description and, where CF has one, a standard name.

One table for every writer: Parquet field metadata (`units`, `long_name`), NetCDF variable
attributes, and the user guide's "Output columns" (docs/user-guide.md; a test checks that it documents every
column here with its units).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Column:
    units: str  # UDUNITS text, "1" for dimensionless, "" for text and flags
    description: str
    standard_name: str = ""  # CF standard name, where one exists


TIME = Column("UTC", "the listening window's opening time", "time")
LAT = Column("degrees_north", "latitude (posterior mean; where ambiguous, the heavier mode's mean)", "latitude")
LON = Column("degrees_east", "longitude, as lat", "longitude")
FLOAT_ID = Column("", "the float's id")

TRACK: dict[str, Column] = {
    "float_id": FLOAT_ID,
    "time": TIME,
    "lat": LAT,
    "lon": LON,
    "sd_km": Column("km", "RMS distance of the posterior from its mean"),
    "smaj_km": Column("km", "one-sigma semi-major axis of the position covariance (x 2.448 = 95% ellipse)"),
    "smin_km": Column("km", "one-sigma semi-minor axis of the position covariance"),
    "angle_deg": Column("degree", "direction of the major axis, clockwise from north"),
    "ess": Column("1", "the filter's effective sample size at the window (particles)"),
    "n_signals": Column("1", "arrival times (TOAs) stored in the window"),
    "loglik": Column("1", "the window's log evidence log p(T_k | T_1..k-1), natural log"),
    "ambiguous": Column("", "true where the posterior splits into two separate modes"),
    "second_mode_km": Column("km", "distance to the second mode, where ambiguous"),
    "status": Column("", "what supports the position: ok, ambiguous, unsupported or recovered"),
}
LABELS: dict[str, Column] = {
    "float_id": FLOAT_ID,
    "time": TIME,
    "rank": Column("1", "the TOA's rank in its window (1 = earliest)"),
    "toa_s": Column("s", "arrival time after the window opened"),
    "beacon_id": Column("", "the most probable source (empty = clutter)"),
    "prob": Column("1", "probability of that label"),
    "p_clutter": Column("1", "probability that the TOA is clutter"),
}
MODES: dict[str, Column] = {
    "float_id": FLOAT_ID,
    "time": TIME,
    "mode": Column("1", "1 = the heavier mode (the one reported in the track), 2 = the other"),
    "lat": Column("degrees_north", "the mode's mean latitude", "latitude"),
    "lon": Column("degrees_east", "the mode's mean longitude", "longitude"),
    "weight": Column("1", "posterior mass of the mode"),
    "sd_km": Column("km", "RMS distance of the mode's particles from its mean"),
}
TABLES: dict[str, dict[str, Column]] = {"track": TRACK, "labels": LABELS, "modes": MODES}


def column(table: str, name: str) -> Column | None:
    """The description of `name` in `table` ("track", "labels", "modes"; a `_filtered`
    suffix is ignored), or None for a column not described here."""
    return TABLES.get(table.removesuffix("_filtered"), {}).get(name)
