"""`rafostrack batch`: track every float of whole mission directories, incrementally, in parallel.

One module per step, each stating in its docstring what it guarantees:

- `discover`: the mission directories under the roots, and the floats each lists;
  outputs mirror the inputs (`OUT/<mission path under its root>/<float_id>/`).
- `plan`: each float's key (inputs, config, version, plots) against the manifest of its
  outputs: skip what is unchanged, say why the rest is redone.
- `execute`: one float tracked into a temporary sibling directory and swapped into place,
  all or nothing, only while this run holds OUT's lock.
- `pool`: the floats in local worker processes (`--jobs`) or on a Dask cluster (`--scheduler`).
- `lock`: one run at a time per OUT, by a kernel lock that a killed run cannot leave behind.
- `report`: progress bar or plain lines, the summary table, `batch-summary.csv`, `batch.log`.
- `findings`: the table values the arrivals contradict, per mission, a source's once for all
  the floats that hear it, and a source's offset, drift or position on their arrivals
  together (`metadata-findings.csv`).
- `array_rounds`: each mission's array fitted on its floats (`rafostrack.mission`), the
  floats tracked again with what it decides (`OUT/<mission>/beacons-calibrated.csv`).
- `overview`: the mission overview, which floats need a look and why (`overview.html`,
  `overview.csv`, `overview.png`; also `rafostrack summary OUT`).
- `run`: `run_batch`, the whole run in order.
"""

from .discover import Mission, discover
from .execute import process_float
from .lock import LOCK_INFO_NAME, LOCK_NAME, BatchLock, LockHeldError
from .plan import FAILED, MANIFEST, PROCESSED, SKIPPED, FloatOutcome, FloatTask, plan
from .pool import run_dask, run_local
from .report import LOG_NAME, SUMMARY_COLUMNS, SUMMARY_NAME, Reporter, summary_table
from .run import BatchResult, default_jobs, run_batch

__all__ = [
    "FAILED",
    "LOCK_INFO_NAME",
    "LOCK_NAME",
    "LOG_NAME",
    "MANIFEST",
    "PROCESSED",
    "SKIPPED",
    "SUMMARY_COLUMNS",
    "SUMMARY_NAME",
    "BatchLock",
    "BatchResult",
    "FloatOutcome",
    "FloatTask",
    "LockHeldError",
    "Mission",
    "Reporter",
    "default_jobs",
    "discover",
    "plan",
    "process_float",
    "run_batch",
    "run_dask",
    "run_local",
    "summary_table",
]
