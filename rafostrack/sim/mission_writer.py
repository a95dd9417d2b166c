"""Write a simulated mission as a CSV mission directory `rafostrack track` reads.

beacons.csv, floats.csv, one arrival file per float (with the true labels as hand labels),
truth/<float_id>.csv and a rafostrack.toml holding the simulated measurement model; the
stress generator's metadata faults in truth/faults.json. Every file is written atomically.
"""

from __future__ import annotations

import csv
import io
import json
import math
import tomllib
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from ..config import load_config, merge_layer
from ..domain import ArrivalRecord, BeaconTable, FloatInfo
from ..io.atomic import write_text_atomic
from ..io.config_report import toml_value

if TYPE_CHECKING:
    from .faults import InjectedFault
    from .simulate import SimulatedMission

_TOA_DECIMALS = 2  # the files' resolution (0.01 s)


def _iso(t: np.datetime64) -> str:
    """ISO-8601 UTC with a Z; '' for NaT; seconds unless the time has a fraction."""
    t = np.datetime64(t).astype("datetime64[ns]")
    if np.isnat(t):
        return ""
    whole = t.astype("int64") % 1_000_000_000 == 0
    return np.datetime_as_string(t, unit="s" if whole else "ns") + "Z"


def _num(x: float) -> str:
    """Shortest text that reads back to the same float ('300', '-58.149'); '' for NaN."""
    x = float(x)
    if math.isnan(x):
        return ""
    return str(int(x)) if x.is_integer() and abs(x) < 1e15 else repr(x)


def _csv(header: list[str], rows: list[list[str]]) -> str:
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(header)
    writer.writerows(rows)
    return buf.getvalue()


def _check_id(kind: str, name: str) -> None:
    if not name or name != name.strip() or any(c in name for c in ',"\n\r/\\'):
        raise ValueError(f'{kind} {name!r} cannot be written (empty, padded, or contains , " / \\ or newline)')


def mission_config_text(mission: SimulatedMission, config_overrides: dict | None = None) -> str:
    """`rafostrack.toml`: the simulation's [model] table, then any further sections/keys.

    Overrides are validated like any config layer; a [model] key among them replaces the
    simulated value (deliberate model mismatch).
    """
    sections: dict[str, dict[str, Any]] = {"model": asdict(mission.model)}
    for name, values in (config_overrides or {}).items():
        if not isinstance(values, dict):
            raise ValueError(f"config_overrides[{name!r}] must be a dict of keys")
        sections.setdefault(name, {}).update(values)
    lines = [
        "# Written by rafostrack.sim.simulate.write_mission. [model] holds the measurement model",
        "# the arrival times were simulated with, so that tracking uses matching settings.",
        f"# Drift: mean velocity + Ornstein-Uhlenbeck eddies (speed sd "
        f"{mission.eddy_speed_km_per_day:g} km/day, timescale {mission.eddy_timescale_days:g} days),",
        "# bridged to the end fix; true tracks are in truth/.",
    ]
    for name, values in sections.items():
        lines += ["", f"[{name}]"] + [f"{key} = {toml_value(v)}" for key, v in values.items()]
    text = "\n".join(lines) + "\n"
    merge_layer(load_config().to_dict(), tomllib.loads(text), "rafostrack.toml (write_mission)")
    return text


def write_mission(mission: SimulatedMission, outdir: Path, config_overrides: dict | None = None) -> None:
    """Write a mission directory (every file atomically):

    beacons.csv, floats.csv, <float_id>.csv (time, toa_s, beacon_id: the true labels as
    hand labels, empty = clutter; a window that stored nothing is one row with empty
    toa_s), truth/<float_id>.csv (time, lat, lon) and rafostrack.toml ([model] as simulated,
    plus `config_overrides`, e.g. {"filter": {"particles": 2000}}).
    """
    config_text = mission_config_text(mission, config_overrides)  # validate before writing
    write_mission_files(mission.beacons, [(sf.info, sf.record, sf.truth) for sf in mission.floats], Path(outdir))
    write_text_atomic(Path(outdir) / "rafostrack.toml", config_text)


def write_mission_files(
    beacons: BeaconTable, floats: list[tuple[FloatInfo, ArrivalRecord, pd.DataFrame]], outdir: Path
) -> None:
    """beacons.csv, floats.csv, the arrival files and truth/<float_id>.csv (see
    `write_mission`), for floats given as (info, record with true labels, truth track)."""
    b = beacons
    for bid in b.beacon_id:
        _check_id("beacon_id", str(bid))
    for info, _, _ in floats:
        _check_id("float_id", info.float_id)
    beacon_rows = [
        [str(b.beacon_id[i]), _num(b.lat[i]), _num(b.lon[i]), _num(b.offset_s[i]), _iso(b.start[i]),
         _iso(b.end[i]), _num(b.drift_s_per_day[i])]
        for i in range(len(b))
    ]  # fmt: skip
    write_text_atomic(
        outdir / "beacons.csv",
        _csv(["beacon_id", "lat", "lon", "offset_s", "start", "end", "drift_s_per_day"], beacon_rows),
    )
    float_rows = [
        [f.float_id, _iso(f.launch_time), _num(f.launch_lat), _num(f.launch_lon), _iso(f.end_time),
         _num(f.end_lat), _num(f.end_lon), _num(f.clock_offset_start_s), _num(f.clock_offset_end_s),
         _num(f.window_s), str(int(f.max_signals))]
        for f, _, _ in floats
    ]  # fmt: skip
    float_header = [
        "float_id", "launch_time", "launch_lat", "launch_lon", "end_time", "end_lat", "end_lon",
        "clock_offset_start_s", "clock_offset_end_s", "window_s", "max_signals",
    ]  # fmt: skip
    write_text_atomic(outdir / "floats.csv", _csv(float_header, float_rows))
    for info, record, truth in floats:
        rows = []
        for w in record.windows:
            when = _iso(w.time)
            if w.n_signals == 0:
                rows.append([when, "", ""])
            labels = w.beacon_id if w.beacon_id is not None else (None,) * w.n_signals
            rows += [[when, f"{t:.{_TOA_DECIMALS}f}", lab or ""] for t, lab in zip(w.toa_s, labels, strict=True)]
        write_text_atomic(outdir / f"{info.float_id}.csv", _csv(["time", "toa_s", "beacon_id"], rows))
        truth_rows = [
            [_iso(t), f"{la:.6f}", f"{lo:.6f}"]
            for t, la, lo in zip(
                truth["time"].to_numpy(dtype="datetime64[ns]"),
                truth["lat"].to_numpy(dtype=float),
                truth["lon"].to_numpy(dtype=float),
                strict=True,
            )
        ]
        write_text_atomic(outdir / "truth" / f"{info.float_id}.csv", _csv(["time", "lat", "lon"], truth_rows))


def write_faults(faults: Sequence[InjectedFault], outdir: Path) -> None:
    """truth/faults.json: the metadata faults written in the tables, one object per fault
    (kind, file, id, field, true, written; `faults.InjectedFault`), [] when none was drawn."""
    text = json.dumps([f.to_json() for f in faults], indent=2) + "\n"
    write_text_atomic(Path(outdir) / "truth" / "faults.json", text)
