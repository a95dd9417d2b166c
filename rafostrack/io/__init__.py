"""Everything that crosses the package's boundary: readers, writers, the output directory.

A mission has three kinds of input, each read by a `Reader` registered here for its file
format: the beacon table (`beacons`), the float table (`floats`) and one arrival record
per float (`arrivals`). A reader is chosen by name (`--format`) or, without one, as the
first registered reader of that kind whose `matches(path)` accepts the file. Readers
validate what they read and raise `InputError` (one line: file, line, field) for what a
user must fix; recoverable oddities go to a `Warnings` list.

To add a format: write a module with its read functions and register them below (see
ARCHITECTURE.md, "Add a reader").
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from ..config import ModelConfig
from ..domain import ArrivalRecord, BeaconTable, FloatInfo
from ..errors import InputError, Warnings, nearest
from . import argo_aux, artoa_mat, artoa_soso, csv_mission

Kind = Literal["beacons", "floats", "arrivals"]


@dataclass(frozen=True)
class Reader:
    """One file format for one kind of input.

    `read` is, by kind: beacons `(path) -> BeaconTable`; floats
    `(path, model: ModelConfig) -> dict[str, FloatInfo]`; arrivals
    `(path, info: FloatInfo, beacons: BeaconTable, warnings: Warnings) -> ArrivalRecord`.
    `float_id(path)` names the float an arrival file belongs to.
    """

    kind: Kind
    format: str
    description: str
    matches: Callable[[Path], bool]
    read: Callable[..., Any]
    float_id: Callable[[Path], str] = lambda path: path.stem


READERS: list[Reader] = []


def register_reader(reader: Reader) -> Reader:
    """Add `reader`; readers registered earlier are tried first."""
    if any(r.kind == reader.kind and r.format == reader.format for r in READERS):
        raise ValueError(f"a {reader.kind} reader for format {reader.format!r} is already registered")
    READERS.append(reader)
    return reader


def formats(kind: Kind) -> list[str]:
    return [r.format for r in READERS if r.kind == kind]


def reader_for(kind: Kind, path: Path, fmt: str | None = None) -> Reader:
    """The reader named `fmt`, or the first one of `kind` that accepts `path`."""
    candidates = [r for r in READERS if r.kind == kind]
    if fmt is not None:
        for r in candidates:
            if r.format == fmt:
                return r
        known = [r.format for r in candidates]
        raise InputError(f"{path}: no {kind} reader for format {fmt!r}{nearest(fmt, known)}; known: {', '.join(known)}")
    for r in candidates:
        if r.matches(Path(path)):
            return r
    listing = "; ".join(f"{r.format} ({r.description})" for r in candidates)
    raise InputError(f"{path}: not a {kind} file of a known format; expected one of: {listing}")


def read_beacons(path: Path, fmt: str | None = None) -> BeaconTable:
    return reader_for("beacons", path, fmt).read(Path(path))


def read_floats(path: Path, model: ModelConfig, fmt: str | None = None) -> dict[str, FloatInfo]:
    return reader_for("floats", path, fmt).read(Path(path), model)


def read_arrivals(
    path: Path, info: FloatInfo, beacons: BeaconTable, warnings: Warnings, fmt: str | None = None
) -> ArrivalRecord:
    return reader_for("arrivals", path, fmt).read(Path(path), info, beacons, warnings)


def check_arrival_file(path: Path, directory_hint: str = "") -> None:
    """InputError unless `path` is a file: a directory is named as one (with an arrival file
    in it as the example of what is expected, and `directory_hint` after), a missing path as
    not found."""
    path = Path(path)
    if path.is_dir():
        tables = ("beacons.csv", "floats.csv")
        arrivals = [r for r in READERS if r.kind == "arrivals"]
        names = sorted(
            p.name
            for p in path.iterdir()
            if p.name not in tables and p.is_file() and any(r.matches(p) for r in arrivals)
        )
        example = path / (names[0] if names else "<float_id>.csv")
        raise InputError(f"{path}: is a directory; expected one float's arrival file (e.g. {example}){directory_hint}")
    if not path.exists():
        raise InputError(f"{path}: file not found; expected one float's arrival file (e.g. <float_id>.csv)")
    if not path.is_file():
        raise InputError(f"{path}: not a regular file; expected one float's arrival file (e.g. <float_id>.csv)")


def float_id_of(path: Path, fmt: str | None = None) -> str:
    """The float an arrival file belongs to (the CSV format: the file's stem)."""
    return reader_for("arrivals", path, fmt).float_id(Path(path))


def _suffix(*suffixes: str) -> Callable[[Path], bool]:
    return lambda path: path.suffix.lower() in suffixes


register_reader(Reader("beacons", "csv", "beacons.csv", _suffix(".csv"), csv_mission.read_beacons))
register_reader(Reader("floats", "csv", "floats.csv", _suffix(".csv"), csv_mission.read_floats))
register_reader(Reader("arrivals", "csv", "<float_id>.csv", _suffix(".csv"), csv_mission.read_arrivals))
register_reader(Reader("beacons", "artoa-soso", "ARTOA soso.dat / *.soso", artoa_soso.matches, artoa_soso.read_beacons))
register_reader(
    Reader(
        "arrivals",
        "artoa-mat",
        "ARTOA/DIMES interim MATLAB *.itm, rf*toa.mat",
        artoa_mat.matches,
        artoa_mat.read_arrivals,
        artoa_mat.float_id,
    )
)
register_reader(
    Reader(
        "arrivals",
        "argo-aux",
        "Argo auxiliary trajectory *_Rtraj_aux.nc",
        argo_aux.matches,
        argo_aux.read_arrivals,
        argo_aux.float_id,
    )
)
