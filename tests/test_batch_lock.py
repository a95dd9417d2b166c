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


def _holds_open(pid: int, path) -> bool:
    """Whether process `pid` has `path` open (Linux: its /proc/<pid>/fd links)."""
    fds = f"/proc/{pid}/fd"
    return any(os.path.realpath(os.path.join(fds, fd)) == os.path.realpath(path) for fd in os.listdir(fds))


def test_the_lock_is_not_inherited_by_child_processes(tmp_path):
    """A process the run starts (a worker, a fork server) must not keep the lock alive after
    the run is gone: only the run's own process holds it. A run takes the lock, starts a
    child that inherits every descriptor it may (`close_fds=False`), and is killed; while the
    child lives on, the next run takes the lock at once (and says the last did not finish)."""
    started = tmp_path / "child.pid"
    run = subprocess.Popen(
        [
            sys.executable,
            "-c",
            textwrap.dedent(
                f"""
                import subprocess, sys, time
                from pathlib import Path
                from rafostrack.batch.lock import BatchLock
                lock = BatchLock(Path({str(tmp_path)!r}), print)
                lock.acquire()
                child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"], close_fds=False)
                Path({str(started)!r}).write_text(str(child.pid))
                time.sleep(60)
                """
            ),
        ]
    )
    child_pid = None
    try:
        deadline = time.monotonic() + 30
        while not (started.exists() and started.read_text()):
            assert run.poll() is None and time.monotonic() < deadline, "the run did not start its child"
            time.sleep(0.01)
        child_pid = int(started.read_text())
        with pytest.raises(LockHeldError, match=f"pid {run.pid} "):  # the run holds it while it lives
            BatchLock(tmp_path, print).acquire()
        if os.path.isdir(f"/proc/{child_pid}/fd"):
            assert _holds_open(run.pid, tmp_path / LOCK_NAME) and not _holds_open(child_pid, tmp_path / LOCK_NAME)
        run.send_signal(signal.SIGKILL)
        run.wait()
        os.kill(child_pid, 0)  # the child outlives the run
        log: list[str] = []
        with BatchLock(tmp_path, log.append) as lock:  # raises LockHeldError if the child held it
            assert json.loads((tmp_path / LOCK_INFO_NAME).read_text())["run_id"] == lock.run_id
        assert len(log) == 1 and f"(pid {run.pid} on " in log[0] and "did not finish" in log[0]
        os.kill(child_pid, 0)  # and still lives: it was not its end that freed the lock
    finally:
        if run.poll() is None:
            run.kill()
            run.wait()
        if child_pid is not None:
            try:
                os.kill(child_pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
