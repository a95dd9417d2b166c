"""A tracked float read back for the mission's array fit: its inputs with the tables as
given, and its output directory's track, labels, calibration and the digest of the table it
was tracked with (`run.json`)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from ..calibrate import INITIAL_CLOCK_RATE_SD_S_PER_DAY, kalman
from ..config import Config
from ..problem import FloatProblem
from ..run.one_float import TrackInputs, load_float
from ..summaries.estimates import Estimate


def _naive_utc(frame: pd.DataFrame) -> pd.DataFrame:
    """The frame with its `time` column as naive UTC (the domain's datetime64)."""
    return frame.assign(time=pd.to_datetime(frame["time"], utc=True).dt.tz_localize(None).astype("datetime64[ns]"))


def estimate_of(out_dir: Path) -> Estimate:
    """The track and labels a float's output directory holds, as the estimate they came from."""
    track = _naive_utc(pd.read_parquet(out_dir / "track.parquet", columns=["time", "lat", "lon", "ambiguous"]))
    labels = _naive_utc(pd.read_parquet(out_dir / "labels.parquet", columns=["time", "toa_s", "beacon_id", "prob"]))
    return Estimate("smoothed", track, labels, pd.DataFrame())


def hyper_of(run: dict[str, Any], config: Config) -> kalman.Hyper:
    """The float's smoother hyperparameters as its calibration left them (run.json), each
    not calibrated there as configured."""
    calibration = run.get("calibration") or {}
    values = calibration.get("values") or {}
    return kalman.Hyper(
        float(values.get("[motion] velocity_sd_km_per_day", config.motion.velocity_sd_km_per_day)),
        float(values.get("[motion] decorrelation_days", config.motion.decorrelation_days)),
        float(values.get("[model] toa_sigma_s", config.model.toa_sigma_s)),
        float(calibration.get("clock_rate_sd_s_per_day", INITIAL_CLOCK_RATE_SD_S_PER_DAY)),
    )


@dataclass(frozen=True)
class TrackedFloat:
    """A float as its outputs left it: its problem with the tables as given, its track and
    labels, and its smoother hyperparameters."""

    problem: FloatProblem
    estimate: Estimate
    hyper: kalman.Hyper
    beacons_sha256: str | None = None  # of the table it was tracked with (run.json)


def tracked_float(inputs: TrackInputs, out_dir: Path) -> TrackedFloat:
    """The float's inputs (the tables as given) and what its output directory holds."""
    problem = load_float(inputs).problem
    run = json.loads((out_dir / "run.json").read_text(encoding="utf-8"))
    tracked_with = (run.get("inputs") or {}).get("beacons") or {}
    return TrackedFloat(problem, estimate_of(out_dir), hyper_of(run, problem.config), tracked_with.get("sha256"))
