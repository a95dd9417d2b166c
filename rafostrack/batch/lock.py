"""OUT's lock: one batch run at a time per output directory, and never a stale lock.

Guarantees:

- A run holds an exclusive kernel lock (`flock`, through `filelock`) on
  `OUT/.rafostrack-batch.lock` for its whole life. The kernel releases it when the process
  ends, however it ends (SIGKILL, out of memory, a crash): a killed run never blocks the next
  one, and there is no lock to take over or delete by hand. The lock file itself stays (an
  empty file); holding it is what counts.
- A second run on the same OUT does not wait and writes nothing: it raises `LockHeldError`
  (the CLI exits with code 2) naming the holder, pid, host and start time, read from
  `OUT/.rafostrack-batch.lock.json`, which the holder writes right after taking the lock and
  removes just before releasing it.
- Each run has a random run id, written in that info file. A worker installs a float only
  while the info file names its run (`execute.py`): when a run is killed and the next one
  takes the lock, anything the killed run's workers still finish is not installed.
- A run that finds the info file of a previous run (that run was killed) says so in the log.
- On a file system without `flock`, the run refuses to start rather than fall back to a lock
  that a killed run could leave behind.
"""

from __future__ import annotations

import errno
import json
import os
import socket
import uuid
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from filelock import FileLock, Timeout

from ..errors import InputError
from ..io.writers import write_json

LOCK_NAME = ".rafostrack-batch.lock"
LOCK_INFO_NAME = ".rafostrack-batch.lock.json"


class LockHeldError(InputError):
    """Another batch run holds OUT's lock (the CLI exits with code 2)."""


def read_lock_info(path: Path) -> dict[str, Any] | None:
    """The holder's info (pid, host, started, run_id), or None when missing or unreadable."""
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def describe_holder(info: dict[str, Any]) -> str:
    return f"pid {info.get('pid')} on {info.get('host')}, started {info.get('started')}"


class BatchLock:
    """The lock of one batch run on OUT; a context manager (see the module docstring)."""

    def __init__(self, out: Path, log: Callable[[str], None]):
        self.path = Path(out) / LOCK_NAME
        self.info_path = Path(out) / LOCK_INFO_NAME
        self.log = log
        self.run_id = uuid.uuid4().hex
        # One attempt, no waiting; fail rather than degrade to a lock that could go stale.
        self._lock = FileLock(self.path, timeout=0, fallback_to_soft=False, preserve_lock_file=True)

    def acquire(self) -> None:
        try:
            self._lock.acquire()
        except Timeout:
            holder = read_lock_info(self.info_path)
            who = f" ({describe_holder(holder)})" if holder else ""
            raise LockHeldError(
                f"{self.path}: another batch run{who} is writing to this output directory; not starting"
            ) from None
        except OSError as exc:
            if exc.errno == errno.ENOSYS:
                raise InputError(
                    f"{self.path}: the file system of the output directory does not support flock locks; "
                    "write OUT to a local or NFS file system"
                ) from None
            raise
        try:
            previous = read_lock_info(self.info_path)
            if previous is not None:
                self.log(
                    f"the previous batch run on this output directory ({describe_holder(previous)}) did not finish; "
                    "its lock was released when it ended"
                )
            write_json(
                self.info_path,
                {
                    "pid": os.getpid(),
                    "host": socket.gethostname(),
                    "started": datetime.now(UTC).isoformat(timespec="seconds"),
                    "run_id": self.run_id,
                },
            )
        except BaseException:
            self._lock.release()
            raise

    def release(self) -> None:
        if not self._lock.is_locked:
            return
        try:
            info = read_lock_info(self.info_path)
            if info is not None and info.get("run_id") == self.run_id:
                self.info_path.unlink(missing_ok=True)
        finally:
            self._lock.release()

    def __enter__(self) -> BatchLock:
        self.acquire()
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()
