"""A computation run beside this process, on a core it leaves idle.

`rafostrack track` on a multi-core machine runs independent pieces of its work in a forked
child while the rest runs here: the last pass's backward filter beside the forward filter
(`one_pass.Tracker.track`: the two share nothing but their inputs, and each draws from its
own generator), the later half of a smoother's windows beside the earlier half (each window
is joined and summarised on its own, `Tracker._smoothed_estimate`), and the source scan's
later candidate passes beside the first (`method._trials`). So the result is the same bits
as computing one piece after the other. Each process runs the compiled kernels on half of
numba's threads (`model.parallel.kernel_threads`), which give the same bits for any thread
count; a piece computed beside forks no further on a machine of two cores.

It is used where there is a core to spare: Linux (whose `fork` copies this process, its
inputs and its compiled kernels, in milliseconds), the main thread (a program that tracks
from several threads of its own keeps them all here), and numba with more than one thread;
a batch worker runs one thread (one float per core), so batches never fork. Anywhere else,
and whenever the child fails (an exception, killed, out of memory), the computation runs
here when its result is asked for: then an error is raised here, with its traceback, and
never lost in a child.

The child is forked while numba's idle worker threads (and, on a terminal, the progress
bar's) exist: it runs only serial kernels, numpy and the pipe back, takes none of their
locks, and leaves at once (`os._exit`), without flushing the standard streams it shares.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import signal
import sys
import threading
from collections.abc import Callable
from multiprocessing.connection import Connection
from multiprocessing.process import BaseProcess
from types import TracebackType
from typing import Any, Generic, TypeVar

import numba

from ..model.parallel import kernel_threads

T = TypeVar("T")


def threads_beside() -> tuple[int, int] | None:
    """numba threads for this process and for a forked child computing beside it, or None
    when this process has no core to spare (one kernel thread) or does not fork (not Linux,
    not the main thread)."""
    threads = numba.get_num_threads()
    main = threading.current_thread() is threading.main_thread()
    if threads < 2 or not main or not sys.platform.startswith("linux"):
        return None
    return threads - threads // 2, threads // 2


class Forked(Generic[T]):
    """`compute()` run in a forked child while the `with` block runs here (module docstring);
    `result()` is its value, computed here instead when there was no child or it failed.

        with Forked(backward_filter) as backward:
            forward = forward_filter()
            back = backward.result()
    """

    def __init__(self, compute: Callable[[], T], *, fork: bool = True) -> None:
        self._compute = compute
        self._fork = fork  # False: computed here (when it is not worth a process)
        self._child: BaseProcess | None = None
        self._receive: Connection | None = None
        self._threads = contextlib.ExitStack()  # this process's share of the kernel threads

    def __enter__(self) -> Forked[T]:
        split = threads_beside() if self._fork else None
        if split is None:
            return self
        mine, its = split
        context = multiprocessing.get_context("fork")
        self._receive, send = context.Pipe(duplex=False)
        self._child = context.Process(target=_child, args=(self._compute, send, its), daemon=True)
        self._child.start()
        send.close()  # the child holds the only writer: its death is end-of-file here
        self._threads.enter_context(kernel_threads(mine))
        return self

    def result(self) -> T:
        """The computation's value (ask once): the child's, or computed here (no child, or
        it failed)."""
        value = self._received()
        return self._compute() if value is None else value[0]

    def _received(self) -> tuple[T] | None:
        """The child's value (in a 1-tuple), or None without a child or when it failed."""
        if self._receive is None:
            return None
        try:
            return self._receive.recv()
        except (EOFError, OSError):  # it died before sending
            return None
        finally:
            self._stop()

    def _stop(self) -> None:
        """End the child (at once: it has sent its value, or it is no longer wanted) and
        give this process its kernel threads back."""
        if self._child is not None:
            self._child.terminate()
            self._child.join()
            self._child = None
        if self._receive is not None:
            self._receive.close()
            self._receive = None
        self._threads.close()

    def __exit__(
        self, kind: type[BaseException] | None, error: BaseException | None, trace: TracebackType | None
    ) -> None:
        self._stop()


def _child(compute: Callable[[], Any], send: Connection, threads: int) -> None:
    """The forked child: compute on `threads` kernel threads and send the value back in a
    1-tuple, or None when computing (or pickling the value) failed; Ctrl-C is the parent's.
    It leaves at once, without the interpreter's and multiprocessing's exit work."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        with kernel_threads(threads):
            value = compute()
        send.send((value,))
    except Exception:
        send.send(None)
    finally:
        send.close()
        os._exit(0)
