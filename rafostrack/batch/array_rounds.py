"""The mission rounds of a batch: fit each mission's array on its tracked floats, and track
them again with the array the mission decided, until it settles.

Round 1 tracks every float with its mission's tables (each float checking only what its own
arrivals can). Then, per mission, the array fit (`rafostrack.mission`) takes every float
whose outputs are current, judges each source's offset, drift and position on all of them
together, and writes `OUT/<mission>/array.csv`, `array.json`, `array.png` and, where it
decided a value, `beacons-calibrated.csv`: the user's beacons.csv with only those cells
changed. The mission's floats are then planned again with that table (its bytes are in each
float's key, so a float already tracked with the same table is skipped) and the array
fitted again on their new labels, at most `MAX_ROUNDS` rounds in all; each round's decided
values and the fit's misfit are logged and kept in `array.json`.

The fit's corrections are always to the tables as given (the floats' labels change between
rounds, not the reference), so a rerun on unchanged inputs decides the same table and
tracks nothing: round 1 of a rerun plans with the calibrated table that `array.json` says
was made from the same beacons.csv.
"""

from __future__ import annotations

import dataclasses
import json
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..io.atomic import write_text_atomic
from ..io.writers import file_digest
from .discover import Mission
from .plan import FloatOutcome
from .pool import OrderedMap

MAX_ROUNDS = 3
ARRAY_JSON = "array.json"


@dataclass(frozen=True)
class ArrayRound:
    """What one mission's array fit decided in one round."""

    mission: str
    floats: int  # those that fit the array (`MissionArray.floats_fitting`)
    decided: list[str]  # "<source> <field>"
    calibrated: Path | None  # the table its floats are to be tracked with (None: as given)
    rms_residual_s: float
    settled: bool  # the table its floats were tracked with holds the decisions already
    trusted: bool = True  # the floats fit one array (`MissionArray.trusted`)
    seconds: float = 0.0  # reading the floats' outputs, the fit and its outputs (wall)
    left_out: int = 0  # floats whose outputs were tracked with another table (`fit_mission`)
    set_aside: tuple[str, ...] = ()  # "<float> <source>": arrivals the fit set aside (`MissionArray.set_aside`)
    moved_sd: float | None = None  # how far its floats' table lies from the decisions (`MissionArray.moved_sd`)
    estimates: dict[str, dict[str, Any]] = dataclasses.field(default_factory=dict)  # per decided value (`_estimates`)


def calibrated_tables(missions: Sequence[Mission], out: Path) -> dict[str, Path]:
    """Per mission, the calibrated table a previous run made from the same beacons.csv."""
    tables = {}
    for mission in missions:
        record = out / mission.name / ARRAY_JSON
        try:
            made = json.loads(record.read_text(encoding="utf-8"))
            if made.get("beacons_sha256") == file_digest(mission.path / "beacons.csv") and made.get("calibrated"):
                tables[mission.name] = out / mission.name / made["calibrated"]
        except (OSError, ValueError, AttributeError):
            continue
    return {name: path for name, path in tables.items() if path.is_file()}


def fit_mission(
    mission: Mission,
    out: Path,
    config_files: tuple[Path, ...],
    overrides: dict[str, Any],
    plots: bool,
    round_: int,
    map_floats: OrderedMap | None = None,
) -> ArrayRound | None:
    """The mission's array fitted on its floats' current outputs and written in
    OUT/<mission>; None when no float has current outputs with enough confident arrivals.
    Current: tracked with the table the mission's floats are planned with (the calibrated
    one a round wrote, else beacons.csv); a float whose tracking in this round failed keeps
    an earlier round's outputs, which the fit leaves out (its "settled" would claim a table
    the float was not tracked with). The calibrated table is rewritten only when the
    decisions moved (`MissionArray.settled_in`), and never in the last
    round: the floats were tracked with the table there is. `map_floats` maps the reading of
    each float's outputs and the fit's per-float work (`pool.ordered_map`; None: here)."""
    from ..mission.outputs import CALIBRATED_NAME, write_array_outputs
    from ..mission.run import fit_mission_array

    started = time.perf_counter()
    mapped = map_floats or map
    tracked, left_out, tracked_with = _current_floats(mission, out, config_files, overrides, mapped)
    fitted_mission = fit_mission_array(tracked, mapped, tracked_with)
    if fitted_mission is None:
        return None
    array = fitted_mission.array
    moved = array.moved_sd(tracked_with) if tracked_with is not None else None
    settled = tracked_with is not None and array.settled_in(tracked_with)
    keep = settled or (tracked_with is not None and round_ == MAX_ROUNDS)
    write_array_outputs(
        array, out / mission.name, mission.path / "beacons.csv", plots=plots, kept=tracked_with if keep else None
    )
    decided = [f"{v.check.id} {v.check.field}" for v in array.decided()]
    sigma = tracked[0].problem.config.model.toa_sigma_s
    rms = array.rms_residual_s(sigma)
    calibrated = out / mission.name / CALIBRATED_NAME
    fitted = ArrayRound(
        mission.name,
        len(array.fit.floats),
        decided,
        calibrated if calibrated.is_file() else None,
        rms,
        settled,
        array.is_trusted,
        time.perf_counter() - started,
        left_out,
        tuple(array.set_aside()),
        moved,
        _estimates(array),
    )
    _record(fitted, mission, out, round_)
    return fitted


def _current_floats(
    mission: Mission, out: Path, config_files: tuple[Path, ...], overrides: dict[str, Any], mapped: Any
) -> tuple[list[Any], int, Any]:
    """The mission's floats whose outputs are current (tracked with the table its floats are
    planned with: the calibrated one a round wrote, else beacons.csv), how many others were
    read (left out), and that calibrated table (None: beacons.csv, or an earlier run's table
    that no longer reads, written anew)."""
    from ..io import read_beacons

    previous = calibrated_tables([mission], out).get(mission.name)
    read = _tracked_floats(mission, out, config_files, overrides, mapped)
    current = file_digest(previous if previous is not None else mission.path / "beacons.csv")
    tracked = [t for t in read if t.beacons_sha256 == current]
    try:
        tracked_with = read_beacons(previous) if previous is not None else None
    except InputError:
        tracked_with = None
    return tracked, len(read) - len(tracked), tracked_with


def _estimates(array: Any) -> dict[str, dict[str, Any]]:
    """Per decided value ("<source> <field>"), this round's estimate and its sd: each
    round's evidence, to follow a value from round to round."""
    found = {}
    for v in array.decided():
        c = v.check
        estimate = " ".join(f"{x:.4f}" for x in c.supported_lat_lon) if c.supported_lat_lon else c.supported
        found[f"{c.id} {c.field}"] = {"estimated": estimate, "sd": c.sd}
    return found


def _tracked_floats(
    mission: Mission, out: Path, config_files: tuple[Path, ...], overrides: dict[str, Any], mapped: Any
) -> list[Any]:
    """The mission's floats with outputs, read back (`_tracked_or_none`; those that cannot
    be are left out), the reading mapped by `mapped`."""
    from ..run.one_float import TrackInputs

    tasks = [
        (TrackInputs(float_path=mission.path / f"{float_id}.csv", config_files=config_files, overrides=overrides),
         out / mission.name / float_id)
        for float_id in sorted(mission.rows)
        if (out / mission.name / float_id / "run.json").is_file()
    ]  # fmt: skip
    return [t for t in mapped(_tracked_or_none, tasks) if t is not None]


def _tracked_or_none(task: tuple[Any, Path]) -> Any:
    """A float's inputs and outputs read back for the fit (`from_outputs.tracked_float`), or
    None where they cannot be: its own outcome says why, and the array rests on the others."""
    from ..mission.from_outputs import tracked_float

    inputs, out_dir = task
    try:
        return tracked_float(inputs, out_dir)
    except (InputError, OSError, KeyError, ValueError):
        return None


def _record(fitted: ArrayRound, mission: Mission, out: Path, round_: int) -> None:
    """`array.json`: the table the fit was made from, what it decided, each round's figures."""
    path = out / mission.name / ARRAY_JSON
    try:
        rounds = json.loads(path.read_text(encoding="utf-8")).get("rounds", []) if round_ > 1 else []
    except (OSError, ValueError):
        rounds = []
    rounds.append({"round": round_, "floats": fitted.floats, "decided": fitted.decided,
                   "rms_residual_s": round(fitted.rms_residual_s, 3), "settled": fitted.settled,
                   "left_out": fitted.left_out, "set_aside": list(fitted.set_aside),
                   "moved_sd": _finite_or_none(fitted.moved_sd), "estimates": fitted.estimates})  # fmt: skip
    record = {
        "beacons_sha256": file_digest(mission.path / "beacons.csv"),
        "calibrated": fitted.calibrated.name if fitted.calibrated is not None else None,
        "decided": fitted.decided,
        "rounds": rounds,
    }
    write_text_atomic(path, json.dumps(record, indent=1) + "\n")


def _finite_or_none(value: float | None) -> float | None:
    """A number for JSON: rounded, None where there is none or it is not finite."""
    return round(value, 2) if value is not None and np.isfinite(value) else None


def round_line(fitted: ArrayRound, round_: int) -> str:
    """One log line of a mission's array fit."""
    from ..mission.array import UNTRUSTED_NOTE

    what = f"decided {', '.join(fitted.decided)}" if fitted.decided else "no table value decided"
    if not fitted.trusted:
        what = f"{UNTRUSTED_NOTE}: nothing decided"
    elif fitted.decided and fitted.moved_sd is not None:
        what += (
            f" (the table they were tracked with {fitted.moved_sd:.2f} sd from these at most)"
            if np.isfinite(fitted.moved_sd)
            else " (not the values decided in the table they were tracked with)"
        )
    if fitted.settled:
        what += "; settled: the floats were tracked with these values"
    elif round_ == MAX_ROUNDS and fitted.decided:
        what += f"; not settled after {MAX_ROUNDS} rounds: the floats keep the table of the round before"
    if fitted.left_out:
        what += f"; {fitted.left_out} float(s) left out: their outputs were tracked with another table"
    if fitted.set_aside:
        what += f"; {len(fitted.set_aside)} float's arrivals of a source set aside (outliers among its floats)"
    return (
        f"mission {fitted.mission}: array fit, round {round_}, {fitted.floats} float(s) fitting it: {what} "
        f"(their weighted rms residual {fitted.rms_residual_s:.2f} s; {fitted.seconds:.1f} s)"
    )


def replaced(outcomes: list[FloatOutcome], newer: list[FloatOutcome]) -> list[FloatOutcome]:
    """The outcomes with each float's newer outcome in place of its older one (a float that
    failed in a later round keeps the failure)."""
    latest = {(o.mission, o.float_id): o for o in newer}
    return [latest.get((o.mission, o.float_id), o) for o in outcomes] + [
        o for o in newer if (o.mission, o.float_id) not in {(p.mission, p.float_id) for p in outcomes}
    ]
