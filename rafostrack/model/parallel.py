"""When the compiled kernels run their particles on several threads.

Each kernel that loops over independent particles (or a smoother's rows) is compiled twice
from one body: a serial loop and a `prange` loop over the same per-item function, so an item's
arithmetic is the same bits either way and whatever the thread count. The threaded one is
used where it pays: numba has more than one thread (`rafostrack track` on a multi-core
machine; a batch worker has one, `batch.workers`) and there are enough items to share.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import numba

PARALLEL_MIN_ITEMS = 256  # fewer: starting the threads costs more than they save


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
