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
- Local workers import the modules the batch process imports, whatever the current directory
  holds (a folder or package named `rafostrack`, say): the fork server they are forked from
  is started with the batch process's own `sys.path` and never the current directory (see
  `_starting_workers`), and each worker checks that its rafostrack is the batch process's.
- What local workers write on stderr reaches batch.log. Before the pool starts, one worker is
  started alone: if it cannot start, no pool is started and every float fails with its
  one-line cause (e.g. `a worker process cannot start: ModuleNotFoundError: No module named
  'rafostrack.cli'`). A worker that dies later fails the floats still unfinished with the last
  line of the last traceback the workers wrote, if any.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import re
import sys
import tempfile
import traceback
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import Any

from ..errors import InputError
from .execute import one_line, process_float
from .plan import FAILED, FloatOutcome, FloatTask
from .workers import environment, single_threaded_math

PACKAGE_DIR = str(Path(__file__).resolve().parents[1])  # the rafostrack this process runs


def check_worker(package_dir: str) -> None:
    """Raise unless this process runs the batch process's rafostrack (`package_dir`)."""
    if PACKAGE_DIR != package_dir:
        raise RuntimeError(f"this worker imports rafostrack from {PACKAGE_DIR}, the batch process from {package_dir}")


def _worker_init(lifeline: Any, package_dir: str) -> None:
    """Local workers die with the batch process: a thread waits on a pipe whose only writer
    is the batch process, and kills this worker when it reads end-of-file (the batch process
    exited or was killed), so no worker of a killed run goes on to install outputs later.
    And a worker runs the batch process's rafostrack or none (`check_worker`)."""
    import signal
    import threading

    check_worker(package_dir)

    def watch() -> None:
        with contextlib.suppress(EOFError, OSError):
            lifeline.recv()
        os.kill(os.getpid(), signal.SIGKILL)

    threading.Thread(target=watch, name="rafostrack-lifeline", daemon=True).start()


class WorkerStderr:
    """The local workers' stderr: an anonymous temporary file, one per batch process, so that
    what a worker writes before it dies (a traceback at start-up, say) reaches batch.log.

    Local workers are forked from multiprocessing's fork server, which lives as long as this
    process and gives them its stderr; the server is started with this file as its stderr
    (`redirect`). A run reads what was appended since it began (`text_since`)."""

    def __init__(self) -> None:
        fd, path = tempfile.mkstemp(prefix="rafostrack-batch-workers-", suffix=".err")
        try:
            self.fd = os.open(path, os.O_RDWR | os.O_APPEND)  # many writers, none overwriting another
        finally:
            os.close(fd)
            os.unlink(path)

    def size(self) -> int:
        return os.fstat(self.fd).st_size

    def text_since(self, offset: int) -> str:
        return os.pread(self.fd, max(0, self.size() - offset), offset).decode("utf-8", errors="replace")

    @contextlib.contextmanager
    def redirect(self) -> Iterator[None]:
        """This process's stderr (file descriptor 2) is the file meanwhile: the processes
        started meanwhile inherit it."""
        sys.stderr.flush()
        saved = os.dup(2)
        os.dup2(self.fd, 2)
        try:
            yield
        finally:
            os.dup2(saved, 2)
            os.close(saved)


_worker_stderr: WorkerStderr | None = None


def worker_stderr() -> WorkerStderr:
    global _worker_stderr
    if _worker_stderr is None:
        _worker_stderr = WorkerStderr()
    return _worker_stderr


@contextlib.contextmanager
def _starting_workers(ctx: multiprocessing.context.BaseContext) -> Iterator[None]:
    """Everything local worker processes (and the fork server they come from) inherit when
    they start: math libraries single-threaded; this process's `sys.path`, in its order, and
    never the current directory; stderr on `worker_stderr()`.

    The fork server is a `python -c` process: the current directory comes first on its
    `sys.path`, and Python 3.11 ignores the `sys.path` multiprocessing hands it (CPython
    gh-117378, fixed in 3.12 and 3.13 releases of late 2024). The modules it preloads, which every worker
    inherits, were therefore those of the current directory: run from a directory holding a
    folder named `rafostrack` (a clone, under cron from ~), every worker failed to start.
    `PYTHONSAFEPATH=1` keeps the current directory out, and `PYTHONPATH` gives the server this
    process's `sys.path` (a '' entry made absolute, as spawned processes get it)."""
    from multiprocessing import resource_tracker

    path = [os.path.abspath(entry) if entry else os.getcwd() for entry in sys.path]
    env = {"PYTHONSAFEPATH": "1", "PYTHONPATH": os.pathsep.join(p for p in path if os.pathsep not in p)}
    resource_tracker.ensure_running()  # started before the redirect: its stderr stays ours
    with environment(env), single_threaded_math(), worker_stderr().redirect():
        if ctx.get_start_method() == "forkserver":
            from multiprocessing import forkserver

            forkserver.ensure_running()
        yield


_EXCEPTION_LINE = re.compile(r"(?:[A-Za-z_]\w*\.)*[A-Za-z_]\w*(?:: .*)?")  # "ImportError: ...", "pkg.Error"


def last_exception_line(text: str) -> str | None:
    """`ExceptionType: message`, the last line of the last Python traceback in `text`."""
    found, in_traceback = None, False
    for line in text.splitlines():
        if line.startswith("Traceback (most recent call last):"):
            in_traceback = True
        elif in_traceback and line and not line[0].isspace() and _EXCEPTION_LINE.fullmatch(line.rstrip()):
            found, in_traceback = line.strip(), False
    return found


def _start_up_failure(ctx: Any, stderr: WorkerStderr) -> str | None:
    """Start one worker-like process alone (as the pool would, then `check_worker`): None when
    it starts, else its one-line cause. Alone, so that its traceback is not interleaved with
    another's (Python writes a traceback to stderr in many pieces): when workers cannot start,
    they all fail alike, and this says why once, cleanly."""
    start = stderr.size()
    with _starting_workers(ctx):
        probe = ctx.Process(target=check_worker, args=(PACKAGE_DIR,), name="rafostrack-batch-start-check")
        probe.start()
    probe.join()
    if probe.exitcode == 0:
        return None
    cause = last_exception_line(stderr.text_since(start))
    return cause or f"it ended with exit code {probe.exitcode}"


def _mp_context() -> multiprocessing.context.BaseContext:
    """`forkserver` where available (safe with threads; the server imports rafostrack once
    and forks each worker from it), else the platform default. Not `fork`: the lifeline pipe's
    writing end must stay in this process only."""
    if "forkserver" in multiprocessing.get_all_start_methods():
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(["rafostrack.batch.pool", "rafostrack.run.one_float"])
        return ctx
    return multiprocessing.get_context()


@contextlib.contextmanager
def _worker_pool(ctx: multiprocessing.context.BaseContext, workers: int) -> Iterator[ProcessPoolExecutor]:
    """A pool of `workers` local worker processes that die with this process (each watches
    a lifeline pipe, `_worker_init`) and run its rafostrack; the pipe closed after the pool."""
    lifeline, keep_alive = ctx.Pipe(duplex=False)  # the workers read; only this process writes
    try:
        with ProcessPoolExecutor(
            max_workers=workers, mp_context=ctx, initializer=_worker_init, initargs=(lifeline, PACKAGE_DIR)
        ) as pool:
            yield pool
    finally:
        keep_alive.close()
        lifeline.close()


def local_workers(jobs: int, n_tasks: int) -> int:
    """How many worker processes `run_local` starts for `n_tasks` tasks: none for none."""
    return min(jobs, n_tasks) if n_tasks else 0


def run_local(
    tasks: Sequence[Any],
    jobs: int,
    fn: Callable[[Any], Any] = process_float,
    on_stderr: Callable[[str], None] | None = None,
) -> Iterator[Any]:
    """Run `fn` (`process_float`) over `tasks` in `jobs` worker processes, yielding outcomes as
    they finish. A worker that dies fails the floats still unfinished, with its last error as
    the reason. At the end, `on_stderr` gets what the workers wrote on stderr, if anything."""
    if not tasks:
        return
    ctx = _mp_context()
    workers = max(1, local_workers(jobs, len(tasks)))
    stderr = worker_stderr()
    stderr_start = stderr.size()
    cannot_start = _start_up_failure(ctx, stderr)
    if cannot_start is not None:
        if on_stderr is not None:
            on_stderr(stderr.text_since(stderr_start))
        for task in tasks:
            yield _crashed(task, f"a worker process cannot start: {cannot_start}")
        return
    try:
        with _worker_pool(ctx, workers) as pool:
            with _starting_workers(ctx):
                futures = {pool.submit(fn, task): task for task in tasks}
            try:
                for future in as_completed(futures):
                    task = futures[future]
                    try:
                        yield future.result()
                    except BrokenProcessPool:
                        cause = last_exception_line(stderr.text_since(stderr_start))
                        if cause:
                            yield _crashed(task, f"a worker process died: {cause}")
                        else:
                            yield _crashed(task, "a worker process died (killed, or out of memory); rerun to retry")
                    except Exception as exc:  # e.g. a task that could not be pickled
                        yield _crashed(task, one_line(exc), traceback.format_exc())
            except BaseException:
                pool.shutdown(wait=True, cancel_futures=True)
                raise
    finally:
        text = stderr.text_since(stderr_start)
        if text and on_stderr is not None:
            on_stderr(text)


OrderedMap = Callable[[Callable[[Any], Any], Iterable[Any]], list[Any]]


@contextlib.contextmanager
def ordered_map(jobs: int, client: Any = None) -> Iterator[OrderedMap]:
    """A map whose results come back in order, over `jobs` local worker processes (started
    as `run_local`'s are) or the Dask cluster of `client`, for work beside the floats'
    tracking (the mission's array fit, `mission.array_fit.float_step`); the builtin map for
    one job. Where the pool breaks (a worker killed, out of memory) or Dask fails, the map
    computes here instead: the same results, more slowly."""
    if client is not None:
        yield _falling_back(lambda fn, items: client.gather(client.map(fn, items, pure=False)))
        return
    if jobs <= 1:
        yield lambda fn, items: list(map(fn, items))
        return
    ctx = _mp_context()
    with _worker_pool(ctx, jobs) as pool:
        with _starting_workers(ctx):  # every worker starts here, with what it inherits
            started = [pool.submit(os.getpid) for _ in range(jobs)]
        try:
            for future in started:
                future.result()
        except BrokenProcessPool:  # the workers cannot start (the floats' outcomes say why)
            yield lambda fn, items: list(map(fn, items))
            return
        yield _falling_back(lambda fn, items: list(pool.map(fn, items)))


def _falling_back(mapped: OrderedMap) -> OrderedMap:
    """`mapped`, or the builtin map where it fails for want of its workers."""

    def map_or_here(fn: Callable[[Any], Any], items: Iterable[Any]) -> list[Any]:
        items = list(items)
        try:
            return mapped(fn, items)
        except (BrokenProcessPool, OSError, TimeoutError):
            return list(map(fn, items))

    return map_or_here


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
