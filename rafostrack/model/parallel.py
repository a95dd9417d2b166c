"""When the compiled kernels run their particles on several threads.

Each kernel that loops over independent particles (or a smoother's rows) is compiled twice
from one body: a serial loop and a `prange` loop over the same per-item function, so an item's
arithmetic is the same bits either way and whatever the thread count. The threaded one is
used where it pays: numba has more than one thread (`rafostrack track` on a multi-core
machine; a batch worker has one, `batch.workers`) and there are enough items to share.

`rafostrack track` takes as many kernel threads as the machine has idle cores when it
starts (`idle_cores`): on a machine whose other work keeps every core busy, threads that
wait for a core to run on cost more than they share (the sample float took 87.6 s on the
default two threads against 34.1 s on one, with both cores busy).
"""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Iterator
from pathlib import Path

import numba

PARALLEL_MIN_ITEMS = 256  # fewer: starting the threads costs more than they save
LOAD_SAMPLE_S = 0.2  # how long the machine's busy cores are measured for


def threaded(items: int) -> bool:
    """Whether a kernel over `items` independent items runs on numba's threads."""
    return items >= PARALLEL_MIN_ITEMS and numba.get_num_threads() > 1


@contextlib.contextmanager
def kernel_threads(count: int) -> Iterator[None]:
    """Run the compiled kernels on `count` of numba's threads (at least 1, at most
    `NUMBA_NUM_THREADS`; this Python thread's setting) for the duration, then as before: one
    for a batch task (one float per core), half for a computation that shares the machine
    with another (`run.forked`)."""
    before = numba.get_num_threads()
    numba.set_num_threads(count)
    try:
        yield
    finally:
        numba.set_num_threads(before)


def usable_cores() -> int:
    """The cores this process may run on (its CPU affinity where the system has one)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def _cpu_times(stat: Path = Path("/proc/stat")) -> tuple[float, float]:
    """(busy, total) jiffies of all cores since boot, from the `cpu` line of /proc/stat
    (idle and iowait are not busy)."""
    fields = [float(v) for v in stat.read_text().split("\n", 1)[0].split()[1:]]
    total = sum(fields[:8])  # user nice system idle iowait irq softirq steal (guests are in user)
    return total - fields[3] - fields[4], total


def busy_cores(sample_s: float = LOAD_SAMPLE_S) -> float:
    """How many of the machine's cores other work keeps busy now: the busy share of every
    core's time over `sample_s` (Linux's /proc/stat), else the 1-minute load average."""
    cores = os.cpu_count() or 1
    try:
        busy0, total0 = _cpu_times()
        time.sleep(sample_s)
        busy1, total1 = _cpu_times()
        return cores * (busy1 - busy0) / max(total1 - total0, 1e-9)
    except (OSError, ValueError, IndexError):
        try:
            return os.getloadavg()[0]
        except OSError:
            return 0.0


def idle_cores(busy: float, usable: int) -> int:
    """The kernel threads worth running: the usable cores not kept busy (at least 1; a core
    busy more than half the time counts as busy)."""
    return int(max(1, min(usable, usable - round(busy))))


def track_threads(asked: int | None) -> int:
    """The kernel threads of one float's run: as `asked` (`--threads`), else the idle cores
    (`idle_cores`); at most numba's (`NUMBA_NUM_THREADS`)."""
    wanted = asked if asked is not None else idle_cores(busy_cores(), usable_cores())
    return max(1, min(wanted, numba.config.NUMBA_NUM_THREADS))  # type: ignore[attr-defined]
