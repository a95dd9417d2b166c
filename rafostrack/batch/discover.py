"""Find the missions under the batch roots, and the floats of each.

Guarantees:

- A mission directory is one holding `beacons.csv` and `floats.csv`; its floats are the ids
  `floats.csv` lists (arrival file `<float_id>.csv` beside them). Every root is walked in
  sorted order; hidden directories and the output directory are not entered.
- Outputs mirror the inputs: a mission's output name is its path relative to its root
  (POSIX style; a root that is itself a mission gives its own name). Two missions, or a
  mission and a float of another, never share an output directory: that is an `InputError`
  (a usage error) before anything is written.
- A `floats.csv` that cannot be read does not stop the others: its mission carries the
  one-line error, and each of its float files fails with it.
- CSV files that `floats.csv` does not list are returned as orphans, to be noted in the log.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import InputError


@dataclass(frozen=True)
class Mission:
    """A mission directory and the floats `floats.csv` lists (with each one's row)."""

    path: Path  # absolute
    name: str  # output path relative to OUT, POSIX style ("m1", "2009/dimes")
    rows: dict[str, dict[str, str]] = field(default_factory=dict)
    error: str | None = None  # floats.csv unreadable: every float file of the mission fails
    orphans: tuple[str, ...] = ()  # CSV files beside them that floats.csv does not list


def discover(roots: Sequence[Path], exclude: Path | None = None) -> list[Mission]:
    """Every mission directory under `roots`, sorted by output name; `InputError` on a bad root
    or when two missions would write the same output directory."""
    from ..io.csv_mission import FLOAT_OPTIONAL, FLOAT_REQUIRED
    from ..io.csv_table import read_csv_table

    exclude = exclude.resolve() if exclude is not None else None
    found: dict[Path, str] = {}
    for root in roots:
        root = Path(root)
        if not root.is_dir():
            raise InputError(f"{root}: not a directory (expected a directory holding missions)")
        root_abs = root.resolve()
        for dirpath, dirnames, filenames in os.walk(root_abs):
            here = Path(dirpath)
            dirnames[:] = sorted(d for d in dirnames if not d.startswith(".") and (here / d).resolve() != exclude)
            if "beacons.csv" in filenames and "floats.csv" in filenames and here not in found:
                rel = here.relative_to(root_abs).as_posix()
                found[here] = root_abs.name if rel == "." else rel
    by_name: dict[str, Path] = {}
    for path, name in found.items():
        if name in by_name:
            raise InputError(
                f"missions {by_name[name]} and {path} would both write OUT/{name}/; give roots whose "
                "missions have distinct relative paths"
            )
        by_name[name] = path

    missions = []
    for name, path in sorted(by_name.items()):
        csvs = sorted(p.stem for p in path.glob("*.csv") if p.name not in ("beacons.csv", "floats.csv"))
        try:
            frame = read_csv_table(path / "floats.csv", FLOAT_REQUIRED, FLOAT_OPTIONAL)
        except InputError as exc:
            failed: dict[str, dict[str, str]] = {fid: {} for fid in csvs} or {"(floats.csv)": {}}
            missions.append(Mission(path, name, failed, error=str(exc)))
            continue
        rows: dict[str, dict[str, str]] = {}
        for record in frame.to_dict("records"):
            rows.setdefault(str(record["float_id"]), {k: str(v) for k, v in record.items()})
        orphans = tuple(fid for fid in csvs if fid not in rows)
        missions.append(Mission(path, name, rows, orphans=orphans))
    for mission in missions:
        for float_id in mission.rows:
            if f"{mission.name}/{float_id}" in by_name:
                raise InputError(
                    f"mission {by_name[f'{mission.name}/{float_id}']} would write OUT/{mission.name}/{float_id}/, "
                    f"the output directory of float {float_id!r} of mission {mission.path}"
                )
    return missions
