"""`rafostrack.batch.lock`: one run per OUT, the holder named, and no stale lock after a kill."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import textwrap
import time

import pytest

from rafostrack.batch.lock import LOCK_INFO_NAME, LOCK_NAME, BatchLock, LockHeldError


def test_a_second_lock_fails_naming_the_holder_and_the_first_release_frees_it(tmp_path):
    first_log: list[str] = []
    first = BatchLock(tmp_path, first_log.append)
    first.acquire()
    info = json.loads((tmp_path / LOCK_INFO_NAME).read_text())
    assert info["pid"] == os.getpid() and info["host"] == socket.gethostname() and info["run_id"] == first.run_id
    second = BatchLock(tmp_path, print)
    with pytest.raises(LockHeldError) as held:
        second.acquire()
    assert f"pid {os.getpid()} on {socket.gethostname()}, started {info['started']}" in str(held.value)
    assert json.loads((tmp_path / LOCK_INFO_NAME).read_text()) == info  # the loser touched nothing

    first.release()
    assert not (tmp_path / LOCK_INFO_NAME).exists() and first_log == []
    with BatchLock(tmp_path, print) as third:  # free again
        assert json.loads((tmp_path / LOCK_INFO_NAME).read_text())["run_id"] == third.run_id != first.run_id


def test_a_holder_killed_with_sigkill_never_blocks_the_next_run(tmp_path):
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            textwrap.dedent(
                f"""
                import time
                from pathlib import Path
                from rafostrack.batch.lock import BatchLock
                lock = BatchLock(Path({str(tmp_path)!r}), print)
                lock.acquire()
                time.sleep(60)
                """
            ),
        ]
    )
    try:
        deadline = time.monotonic() + 30
        while not (tmp_path / LOCK_INFO_NAME).exists():
            assert holder.poll() is None and time.monotonic() < deadline, "the holder did not take the lock"
            time.sleep(0.01)
        with pytest.raises(LockHeldError, match=f"pid {holder.pid} "):
            BatchLock(tmp_path, print).acquire()
    finally:
        holder.send_signal(signal.SIGKILL)
        holder.wait()
    assert (tmp_path / LOCK_NAME).exists() and (tmp_path / LOCK_INFO_NAME).exists()  # left as they were
    log: list[str] = []
    with BatchLock(tmp_path, log.append) as lock:
        assert json.loads((tmp_path / LOCK_INFO_NAME).read_text())["run_id"] == lock.run_id
    assert len(log) == 1 and f"(pid {holder.pid} on {socket.gethostname()}" in log[0] and "did not finish" in log[0]


def test_the_lock_is_not_inherited_by_child_processes(tmp_path):
    """A process the run starts (a worker, a fork server) must not keep the lock alive after
    the run is gone: only the run's own process holds it."""
    child = None
    with BatchLock(tmp_path, print):
        child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"], close_fds=False)
    try:
        # The run released the lock while its child lives on: the child does not hold it.
        with BatchLock(tmp_path, print):
            pass
    finally:
        child.kill()
        child.wait()
