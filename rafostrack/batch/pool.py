"""Run the per-float tasks in parallel: local worker processes, or a Dask cluster.

Guarantees:

- `run_local` and `run_dask` yield one outcome per task, as the tasks finish; a task never
  disappears. A local worker that dies (killed, out of memory) fails the floats still
  unfinished, with a one-line reason; a Dask error fails its float with the error's first line.
- Local workers are started with their math libraries single-threaded (`OMP_NUM_THREADS`,
  `OPENBLAS_NUM_THREADS`, ... = 1 unless the user set them), as Dask workers are; the batch
  process's own environment is left as it was.
- Local workers die with the batch process, however it ends: each watches a pipe whose only
  writer is the batch process, and kills itself when the pipe closes. So no worker of a
  killed run goes on tracking, nor installs a float later.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import traceback
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from typing import Any

from ..errors import InputError
from ..workers import single_threaded_math
from .execute import one_line, process_float
from .plan import FAILED, FloatOutcome, FloatTask


def _worker_init(lifeline: Any) -> None:
    """Local workers die with the batch process: a thread waits on a pipe whose only writer
    is the batch process, and kills this worker when it reads end-of-file (the batch process
    exited or was killed), so no worker of a killed run goes on to install outputs later."""
    import signal
    import threading

    def watch() -> None:
        with contextlib.suppress(EOFError, OSError):
            lifeline.recv()
        os.kill(os.getpid(), signal.SIGKILL)

    threading.Thread(target=watch, name="rafostrack-lifeline", daemon=True).start()


def _mp_context() -> multiprocessing.context.BaseContext:
    """`forkserver` where available (safe with threads; the server imports rafostrack once
    and forks each worker from it), else the platform default. Not `fork`: the lifeline pipe's
    writing end must stay in this process only."""
    if "forkserver" in multiprocessing.get_all_start_methods():
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(["rafostrack.batch.pool", "rafostrack.pipeline"])
        return ctx
    return multiprocessing.get_context()


def run_local(tasks: Sequence[Any], jobs: int, fn: Callable[[Any], Any] = process_float) -> Iterator[Any]:
    """Run `fn` (`process_float`) over `tasks` in `jobs` worker processes, yielding outcomes as
    they finish. A worker that dies (killed, out of memory) fails the floats still unfinished."""
    if not tasks:
        return
    ctx = _mp_context()
    workers = max(1, min(jobs, len(tasks)))
    lifeline, keep_alive = ctx.Pipe(duplex=False)  # the workers read; only this process writes
    try:
        with ProcessPoolExecutor(
            max_workers=workers, mp_context=ctx, initializer=_worker_init, initargs=(lifeline,)
        ) as pool:
            with single_threaded_math():
                if ctx.get_start_method() == "forkserver":  # workers inherit the server's environment
                    from multiprocessing import forkserver

                    forkserver.ensure_running()
                futures = {pool.submit(fn, task): task for task in tasks}
            try:
                for future in as_completed(futures):
                    task = futures[future]
                    try:
                        yield future.result()
                    except BrokenProcessPool:
                        yield _crashed(task, "a worker process died (killed, or out of memory); rerun to retry")
                    except Exception as exc:  # e.g. a task that could not be pickled
                        yield _crashed(task, one_line(exc), traceback.format_exc())
            except BaseException:
                pool.shutdown(wait=True, cancel_futures=True)
                raise
    finally:
        keep_alive.close()
        lifeline.close()


def dask_client(address: str) -> Any:
    """A `distributed.Client` connected to the scheduler at `address` (`InputError` when Dask
    is not installed or the scheduler cannot be reached)."""
    try:
        from distributed import Client
    except ImportError:
        raise InputError("--scheduler needs Dask: pip install 'rafostrack[dask]'") from None
    try:
        return Client(address, timeout="20s")
    except (OSError, TimeoutError, ValueError, TypeError) as exc:
        raise InputError(f"--scheduler {address}: cannot connect to a Dask scheduler: {one_line(exc)}") from None


def run_dask(tasks: Sequence[FloatTask], client: Any) -> Iterator[FloatOutcome]:
    """Submit `process_float` per float to a Dask cluster, yielding outcomes as they finish
    (workers need rafostrack installed and the same paths to the inputs and to OUT)."""
    from distributed import as_completed as dask_as_completed

    if not tasks:
        return
    futures = client.map(process_float, list(tasks), pure=False)
    by_key = {future.key: task for future, task in zip(futures, tasks, strict=True)}
    for future in dask_as_completed(futures):
        task = by_key[future.key]
        try:
            yield future.result()
        except Exception as exc:  # KilledWorker, lost connection, ...
            yield _crashed(task, f"Dask: {one_line(exc)}", traceback.format_exc())


def _crashed(task: FloatTask, reason: str, detail: str = "") -> FloatOutcome:
    return FloatOutcome(task.mission, task.float_id, FAILED, reason, detail=detail)
