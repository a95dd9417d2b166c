"""One float's row of the mission overview: what its outputs say (track, labels, run.json).

From track.parquet: the windows and their shares by `status` (ok, ambiguous, recovered,
unsupported), the median and the 95th percentile of `sd_km`. From labels.parquet: the
shares of the TOAs labelled to a beacon and called clutter (`beacon_id` empty; the two add
up to 1). From run.json: the sound speed and the TOA sd the last pass used (calibrated, or
as configured), the RMS residual of the calibration's direct arrivals, the float clock's
drift over the record (the end offset used minus the launch offset used,
`metadata_checks`), the warnings counted by kind (`warning_counts`: run.json's
`warning_kinds`, each set where its warning was made, `errors.WarningKind`; never read from
the wording) and the table values its arrivals contradict (`metadata_checks` read by
`run_checks.parse_checks`). `FloatRow.row` is the float's row of overview.csv.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from ..calibrate.metadata_checks import CONTRADICTED
from ..errors import WarningKind
from ..io.writers import csv_text, file_digest
from ..plots.mission_map import OK
from .findings import table_place, value_texts
from .run_checks import Check, number, parse_checks

OVERVIEW_CSV = "overview.csv"
STATUSES = ("ok", "ambiguous", "recovered", "unsupported")  # track.parquet `status`
OVERVIEW_COLUMNS = (
    "look",
    "mission",
    "float_id",
    "reasons",
    "windows",
    *(f"share_{s}" for s in STATUSES),
    "sd_km_median",
    "sd_km_p95",
    "share_labelled",
    "share_clutter",
    "sound_speed_m_s",
    "sound_speed_calibrated",
    "clock_drift_s",
    "toa_sigma_s",
    "toa_sigma_calibrated",
    "toa_residual_rms_s",
    "n_warnings",
    "warning_kinds",
    "n_contradicted",
    "metadata_contradicted",
    "output",
)


@dataclass(frozen=True)
class FloatRow:
    """One float of the overview: what its outputs say, and whether it needs a look."""

    mission: str
    float_id: str
    output: str = ""  # its output directory ("" when it failed)
    failed: str = ""  # the batch's reason, when it failed
    unreadable: str = ""  # why its outputs cannot be read
    windows: int | None = None
    shares: Mapping[str, float] = field(default_factory=dict)  # status -> share of windows
    sd_km_median: float | None = None
    sd_km_p95: float | None = None
    labelled_share: float | None = None
    clutter_share: float | None = None
    sound_speed_m_s: float | None = None
    sound_speed_calibrated: bool | None = None
    clock_drift_s: float | None = None
    toa_sigma_s: float | None = None
    toa_sigma_calibrated: bool | None = None
    toa_residual_rms_s: float | None = None
    warning_kinds: Mapping[str, int] = field(default_factory=dict)  # kind (`errors.WarningKind`) -> warnings
    contradicted: tuple[tuple[str, str], ...] = ()  # per contradicted table value: what, given vs arrivals
    beacons_file: str = ""  # the beacons.csv it was tracked with (run.json), for the map
    lat: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0), repr=False, compare=False)
    lon: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0), repr=False, compare=False)
    look: str = OK
    reasons: tuple[str, ...] = ()

    @property
    def n_warnings(self) -> int:
        return sum(self.warning_kinds.values())

    def contradicted_text(self) -> str:
        """'beacons.csv line 4: offset_s of US1-3: given 1530.0 s, arrivals 1497.2 s; ...'."""
        return "; ".join(f"{what}: {detail}" for what, detail in self.contradicted)

    def row(self) -> dict[str, Any]:
        """One row of overview.csv (shares as fractions; empty where unknown)."""
        known = self.windows is not None and not self.unreadable
        return dict(
            look=self.look,
            mission=self.mission,
            float_id=self.float_id,
            reasons="; ".join(self.reasons),
            windows=_cell(self.windows),
            **{f"share_{s}": _cell(self.shares.get(s, 0.0) if known else None, 4) for s in STATUSES},
            sd_km_median=_cell(self.sd_km_median, 3),
            sd_km_p95=_cell(self.sd_km_p95, 3),
            share_labelled=_cell(self.labelled_share, 4),
            share_clutter=_cell(self.clutter_share, 4),
            sound_speed_m_s=_cell(self.sound_speed_m_s, 2),
            sound_speed_calibrated=_cell(self.sound_speed_calibrated),
            clock_drift_s=_cell(self.clock_drift_s, 3),
            toa_sigma_s=_cell(self.toa_sigma_s, 3),
            toa_sigma_calibrated=_cell(self.toa_sigma_calibrated),
            toa_residual_rms_s=_cell(self.toa_residual_rms_s, 3),
            n_warnings=self.n_warnings if known else "",
            warning_kinds=kinds_text(self.warning_kinds, "=", ";"),
            n_contradicted=len(self.contradicted) if known else "",
            metadata_contradicted=self.contradicted_text(),
            output=self.output,
        )


def _cell(value: float | int | bool | None, digits: int | None = None) -> str | float | int:
    """A CSV cell: empty for None, booleans as true/false, floats rounded to `digits`."""
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if digits is not None and isinstance(value, float):
        return round(value, digits)
    return value


def kinds_text(kinds: Mapping[str, int], sep: str = " ", join: str = ", ") -> str:
    """'metadata 2, gaps 1' (or 'metadata=2;gaps=1' for the CSV), most frequent first."""
    ordered = sorted(kinds.items(), key=lambda kv: (-kv[1], kv[0]))
    return join.join(f"{kind}{sep}{n}" for kind, n in ordered)


def track_stats(track: pd.DataFrame) -> dict[str, Any]:
    """Windows, the share of each status among them, the median and 95th percentile of sd_km."""
    n = len(track)
    status = track["status"].astype(str) if "status" in track else pd.Series([], dtype=str)
    counts = status.value_counts()
    sd = pd.to_numeric(track.get("sd_km", pd.Series([], dtype=float)), errors="coerce").to_numpy(dtype=float)
    sd = sd[np.isfinite(sd)]
    return dict(
        windows=n,
        shares={str(s): int(c) / n for s, c in counts.items()} if n else {},
        sd_km_median=float(np.median(sd)) if len(sd) else None,
        sd_km_p95=float(np.percentile(sd, 95)) if len(sd) else None,
    )


def label_stats(labels: pd.DataFrame) -> dict[str, Any]:
    """The shares of the TOAs labelled to a beacon and called clutter (`beacon_id` empty)."""
    if not len(labels):
        return dict(labelled_share=None, clutter_share=None)
    labelled = float(labels["beacon_id"].notna().mean())
    return dict(labelled_share=labelled, clutter_share=1.0 - labelled)


def run_values(run: Mapping[str, Any], float_id: str) -> dict[str, Any]:
    """From run.json: sound speed and TOA sd used (calibrated or configured), the calibration's
    residual RMS, the clock's drift, the warnings by kind, the contradicted table values."""
    calibration = _mapping(run.get("calibration"))
    fitted = _mapping(calibration.get("values"))
    model = _mapping(_mapping(run.get("config")).get("model"))
    speed, speed_fitted = _used(fitted, model, "sound_speed_m_s")
    sigma, sigma_fitted = _used(fitted, model, "toa_sigma_s")
    contradicted = [c for c in parse_checks(run, float_id) if c.outcome == CONTRADICTED]
    return dict(
        sound_speed_m_s=speed,
        sound_speed_calibrated=speed_fitted,
        toa_sigma_s=sigma,
        toa_sigma_calibrated=sigma_fitted,
        toa_residual_rms_s=number(calibration.get("residual_rms_s")),
        clock_drift_s=clock_drift_s(run, float_id),
        warning_kinds=warning_counts(run),
        contradicted=tuple(contradiction(c) for c in contradicted),
    )


def warning_counts(run: Mapping[str, Any]) -> dict[str, int]:
    """run.json's warnings counted by kind: its `warning_kinds`, one per warning in the same
    order (`errors.WarningKind`, set where the warning was made). A run.json without the key
    (written by an older version), or whose kinds do not pair with its warnings: each
    warning counted as "other"."""
    warnings = run.get("warnings")
    kinds = run.get("warning_kinds")
    n = len(warnings) if isinstance(warnings, list) else 0
    if not isinstance(kinds, list) or len(kinds) != n:
        kinds = [WarningKind.OTHER] * n
    counts: dict[str, int] = {}
    for kind in kinds:
        name = str(kind) if isinstance(kind, str) and kind else str(WarningKind.OTHER)
        counts[name] = counts.get(name, 0) + 1
    return counts


def _mapping(value: Any) -> Mapping[str, Any]:
    """`value` when it is a mapping (a JSON object), else an empty one."""
    return value if isinstance(value, Mapping) else {}


def _used(fitted: Mapping[str, Any], model: Mapping[str, Any], key: str) -> tuple[float | None, bool | None]:
    """The value the last pass used for `[model] key`: the calibration's, else the configured."""
    value = number(fitted.get(f"[model] {key}"))
    if value is not None:
        return value, True
    value = number(model.get(key))
    return value, (False if value is not None else None)


def clock_drift_s(run: Mapping[str, Any], float_id: str) -> float | None:
    """The float clock's drift over the record, s: the end offset used minus the launch
    offset used (`metadata_checks` of the float's own clock; None when either is missing)."""
    used: dict[str, float] = {}
    entries = run.get("metadata_checks")
    for entry in entries if isinstance(entries, list) else []:
        if isinstance(entry, Mapping) and str(entry.get("id")) == float_id:
            value = number(entry.get("used"))
            if value is not None:
                used[str(entry.get("field"))] = value
    if "clock_offset_start_s" not in used or "clock_offset_end_s" not in used:
        return None
    return used["clock_offset_end_s"] - used["clock_offset_start_s"]


def contradiction(check: Check) -> tuple[str, str]:
    """What a contradicted check names and what it says: ('beacons.csv line 4: offset_s of
    US1-3', 'given 1530.0 s, arrivals 1497.2 s'); a position as latitude, longitude."""
    given, supported = value_texts(check)
    return f"{table_place(check.file, check.line)}: {check.field} of {check.id}", f"given {given}, arrivals {supported}"


def summarise_float(mission: str, float_id: str, output: Path) -> FloatRow:
    """The row of one tracked float, from track.parquet, labels.parquet and run.json in
    `output`; a row saying why when they cannot be read."""
    row = FloatRow(mission, float_id, output=str(output))
    try:
        run = json.loads((output / "run.json").read_text(encoding="utf-8"))
        if not isinstance(run, dict):
            raise ValueError("run.json does not hold an object")
        track = pd.read_parquet(output / "track.parquet", columns=["lat", "lon", "sd_km", "status"])
        labels = pd.read_parquet(output / "labels.parquet", columns=["beacon_id"])
    except (OSError, ValueError, KeyError) as exc:  # pyarrow's errors are OSError / ValueError
        reason = " ".join(str(getattr(exc, "strerror", None) or exc).splitlines())
        return dataclasses.replace(row, unreadable=f"{output}: {reason}")
    return dataclasses.replace(
        row,
        **track_stats(track),
        **label_stats(labels),
        **run_values(run, float_id),
        beacons_file=recorded_input(run, "beacons", output),
        lat=track["lat"].to_numpy(dtype=float),
        lon=track["lon"].to_numpy(dtype=float),
    )


def recorded_input(run: Mapping[str, Any], key: str, output: Path) -> str:
    """The path of run.json's input `key` ("" when none). A relative one is relative to the
    folder the float was tracked from, which the output directory usually lies in: it is
    looked for against `output` and each folder above it, then the current one, a file whose
    digest is the recorded one first; as recorded when none is there."""
    entry = _mapping(_mapping(run.get("inputs")).get(key))
    text = str(entry.get("path") or "")
    recorded = Path(text)
    if not text or recorded.is_absolute():
        return text
    bases = (output, *Path(output).absolute().parents, Path.cwd())
    found = [base / recorded for base in bases if (base / recorded).is_file()]
    same = [p for p in found if file_digest(p) == entry.get("sha256")]
    return str((same or found or [recorded])[0])


def overview_csv(rows: Sequence[FloatRow]) -> str:
    """The text of overview.csv: a header (`OVERVIEW_COLUMNS`) and one row per float, in order."""
    return csv_text(OVERVIEW_COLUMNS, (r.row() for r in rows))
