"""Track one float into its output directory, all or nothing (runs in a worker, local or Dask).

Guarantees:

- `process_float` never raises: any failure (a bad input file, any exception) comes back as
  a `failed` outcome with a one-line reason (and, for an unexpected exception, its traceback
  for batch.log). The float's previous outputs, if any, are left as they were.
- The float is written into a hidden sibling `OUT/<mission>/.<float_id>.tmp-<pid>/`; its
  `batch-manifest.json` is written last, then the directory is swapped into place by
  renames (old directory renamed aside, new one renamed in, old deleted). So
  `OUT/<mission>/<float_id>/` is always a whole result, old or new, whenever the run is
  killed; the next run removes what is left aside (`run.py`).
- Outputs are installed only while OUT's lock info names this task's run (`lock.py`): a
  worker of a run that has lost the lock installs nothing.
- A worker whose rafostrack version is not the one the batch process planned with (a Dask
  worker with another installation) fails the float rather than write outputs the manifest
  would attribute to another version.
- The outputs depend only on the task (the float's random numbers come from the seed and
  the float id), not on the worker, the order or the number of workers.
"""

from __future__ import annotations

import os
import shutil
import socket
import time
import traceback
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .. import __version__
from ..errors import InputError
from ..io.outdir import staging_dir, swap_into_place
from ..io.writers import write_json
from .lock import read_lock_info
from .plan import FAILED, MANIFEST, MANIFEST_FORMAT, PROCESSED, FloatOutcome, FloatTask

if TYPE_CHECKING:  # a worker imports the pipeline when it tracks its first float
    from ..run.one_float import TrackInputs


def process_float(task: FloatTask) -> FloatOutcome:
    """Track one float into a temporary sibling directory, write its manifest last, then swap
    it into place. Never raises: a failure is returned as an outcome with a one-line reason."""
    from ..model.parallel import kernel_threads
    from ..run.one_float import TrackInputs, track_float

    started = time.perf_counter()
    planned_version = task.components.get("rafostrack_version", __version__)
    if planned_version != __version__:  # a Dask worker with another installation, say
        reason = f"this worker runs rafostrack {__version__}, the batch process {planned_version}; install the same"
        return FloatOutcome(task.mission, task.float_id, FAILED, reason)
    staging = staging_dir(task.out_dir)
    try:
        if staging.exists():
            shutil.rmtree(staging)
        inputs = TrackInputs(
            float_path=task.float_path,
            beacons_path=task.beacons_path,
            config_files=task.config_files,
            overrides=task.overrides,
        )
        with kernel_threads(1):  # one float per core
            result = track_float(inputs, staging, plots=task.plots)
        built = Path(result.out_dir)
        # last: the manifest's presence marks the directory complete
        write_json(built / MANIFEST, float_manifest(task, inputs, built))
        check_run_holds_lock(task)
        swap_into_place(built, task.out_dir)
        warnings = len(result.run.get("warnings", ()))
        return FloatOutcome(
            task.mission,
            task.float_id,
            PROCESSED,
            task.why,
            seconds=time.perf_counter() - started,
            warnings=warnings,
            output=str(task.out_dir),
        )
    except InputError as exc:
        return FloatOutcome(task.mission, task.float_id, FAILED, str(exc), seconds=time.perf_counter() - started)
    except Exception as exc:
        return FloatOutcome(
            task.mission,
            task.float_id,
            FAILED,
            one_line(exc),
            seconds=time.perf_counter() - started,
            detail=traceback.format_exc(),
        )
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def float_manifest(task: FloatTask, inputs: TrackInputs, built: Path) -> dict[str, Any]:
    """The float's `batch-manifest.json`: its task, inputs and the files built in `built`."""
    files = {p.name: p.stat().st_size for p in sorted(built.iterdir()) if p.is_file()}
    return {
        "format": MANIFEST_FORMAT,
        "key": task.key,
        "components": task.components,
        "mission": task.mission,
        "float_id": task.float_id,
        "inputs": {
            "float_file": str(task.float_path),
            "config_files": [str(p) for p in inputs.config_layers()],
        },
        "files": files,
        "finished": datetime.now(UTC).isoformat(timespec="seconds"),
        "host": socket.gethostname(),
        "pid": os.getpid(),
    }


def one_line(exc: BaseException) -> str:
    """`ExceptionType: first line of its message`."""
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0]}" if text else type(exc).__name__


def check_run_holds_lock(task: FloatTask) -> None:
    """Refuse to install outputs when this run no longer holds OUT's lock (it was killed and
    another run took the lock while this worker went on)."""
    if not task.run_id:
        return
    holder = read_lock_info(task.lock_info_path)
    if holder is None or holder.get("run_id") != task.run_id:
        raise RuntimeError(f"{task.lock_info_path}: this batch run no longer holds the lock; outputs not installed")
