"""Write a float's results: Parquet tables with run metadata, and `run.json`.

Every file is written atomically (temporary name, then rename).
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from .atomic import atomic_path, write_text_atomic
from .columns import column

METADATA_PREFIX = "rafostrack."


def write_parquet(frame: pd.DataFrame, path: Path, metadata: dict[str, Any], table_name: str | None = None) -> None:
    """Write `frame` with `time` as a UTC timestamp and `metadata` (JSON values) in the schema.

    Metadata keys are prefixed `rafostrack.`; read them back with `read_metadata`. With
    `table_name` ("track", "labels", "modes"), each described column carries its `units`,
    `long_name` (and CF `standard_name`) as Parquet field metadata (`io.columns`).
    """
    frame = frame.copy()
    if "time" in frame:
        frame["time"] = pd.to_datetime(frame["time"]).dt.tz_localize("UTC")
    table = pa.Table.from_pandas(frame, preserve_index=False)
    if table_name is not None:
        table = table.cast(pa.schema([_described(f, table_name) for f in table.schema], table.schema.metadata))
    extra = {f"{METADATA_PREFIX}{k}".encode(): json.dumps(v, sort_keys=True).encode() for k, v in metadata.items()}
    table = table.replace_schema_metadata({**(table.schema.metadata or {}), **extra})
    with atomic_path(path) as tmp:
        pq.write_table(table, tmp)


def _described(field: pa.Field, table_name: str) -> pa.Field:
    spec = column(table_name, field.name)
    if spec is None:
        return field
    meta = {"units": spec.units, "long_name": spec.description}
    if spec.standard_name:
        meta["standard_name"] = spec.standard_name
    return field.with_metadata({k.encode(): v.encode() for k, v in meta.items()})


def read_metadata(path: Path) -> dict[str, Any]:
    """The `rafostrack.*` schema metadata of a Parquet file written by `write_parquet`."""
    raw = pq.read_schema(path).metadata or {}
    return {
        k.decode()[len(METADATA_PREFIX) :]: json.loads(v)
        for k, v in raw.items()
        if k.decode().startswith(METADATA_PREFIX)
    }


def write_json(path: Path, payload: dict[str, Any]) -> None:
    write_text_atomic(path, json.dumps(payload, indent=2, sort_keys=True, default=str) + "\n")


def file_digest(path: Path) -> str:
    """SHA-256 of a file's bytes, hex."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def csv_text(columns: Sequence[str], rows: Iterable[Mapping[str, Any]]) -> str:
    """The text of a CSV table: a header of `columns`, then one line per row (keyed by column)."""
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(columns), lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return buf.getvalue()
