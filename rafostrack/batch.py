"""`rafostrack batch`: track every float of whole mission directories, incrementally, in parallel.

Four steps, each a function here:

- **discover**: a mission directory is one holding `beacons.csv` and `floats.csv`; its floats
  are the ids of `floats.csv` (arrival file `<float_id>.csv` beside them). Every root is
  walked (hidden directories and the output directory are not entered). Outputs mirror the
  inputs: `OUT/<mission path relative to its root>/<float_id>/` (a root that is itself a
  mission gives `OUT/<its name>/`).
- **plan**: each float gets a key, the SHA-256 over its arrival file's bytes, the bytes of
  `beacons.csv`, its own row of `floats.csv`, the effective config (every layer, as `track`
  loads it), the package version and whether plots are made. The key is stored in the
  float's output directory as `batch-manifest.json`, written last: a float whose manifest
  holds the same key (and whose listed files are all there) is complete and skipped.
- **execute**: the per-float function `process_float` runs in local worker processes
  (`concurrent.futures.ProcessPoolExecutor`) or on a Dask cluster (`--scheduler`). It writes
  into a temporary sibling `OUT/<mission>/.<float_id>.tmp-<pid>/` and swaps the finished
  directory into place by renames, so `OUT/<mission>/<float_id>/` is always either the old
  complete result or the new complete one. Any exception fails that float alone.
- **report**: a progress bar on a terminal, plain log lines otherwise (cron); a summary
  table; `OUT/batch-summary.csv` and `OUT/batch.log`, written atomically.

A lock file `OUT/.rafostrack-batch.lock` (pid, host, start time) keeps two runs from writing
the same OUT; a lock left by a killed run (its pid is gone on this host) is taken over with
a message. Temporary directories left by a killed run are removed by the next one.
"""

from __future__ import annotations

import contextlib
import csv
import hashlib
import io
import json
import multiprocessing
import os
import re
import shutil
import socket
import sys
import time
import traceback
import uuid
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, TextIO

from . import __version__
from .config import load_config
from .errors import InputError
from .io.writers import file_digest, write_json
from .workers import single_threaded_math

MANIFEST = "batch-manifest.json"
LOCK_NAME = ".rafostrack-batch.lock"
SUMMARY_NAME = "batch-summary.csv"
LOG_NAME = "batch.log"
MANIFEST_FORMAT = 1
SUMMARY_COLUMNS = ("mission", "float_id", "status", "reason", "seconds", "warnings", "output")

PROCESSED, SKIPPED, FAILED = "processed", "skipped", "failed"

_STALE_DIR = re.compile(r"^\..+\.(tmp|trash)-\d+$")  # .<float_id>.tmp-<pid>, .<float_id>.trash-<pid>
_STALE_FILE = re.compile(r"^\..+\.tmp$")  # atomic_path's temporary files


# --------------------------------------------------------------------------------------
# Discovery


@dataclass(frozen=True)
class Mission:
    """A mission directory and the floats `floats.csv` lists (with each one's row)."""

    path: Path  # absolute
    name: str  # output path relative to OUT, POSIX style ("m1", "2009/dimes")
    rows: dict[str, dict[str, str]] = field(default_factory=dict)
    error: str | None = None  # floats.csv unreadable: every float file of the mission fails
    orphans: tuple[str, ...] = ()  # CSV files beside them that floats.csv does not list


def discover(roots: Sequence[Path], exclude: Path | None = None) -> list[Mission]:
    """Every mission directory under `roots`, sorted by output name; `InputError` on a bad root
    or when two missions would write the same output directory."""
    from .io.csv_mission import FLOAT_OPTIONAL, FLOAT_REQUIRED
    from .io.csv_table import read_csv_table

    exclude = exclude.resolve() if exclude is not None else None
    found: dict[Path, str] = {}
    for root in roots:
        root = Path(root)
        if not root.is_dir():
            raise InputError(f"{root}: not a directory (expected a directory holding missions)")
        root_abs = root.resolve()
        for dirpath, dirnames, filenames in os.walk(root_abs):
            here = Path(dirpath)
            dirnames[:] = sorted(d for d in dirnames if not d.startswith(".") and (here / d).resolve() != exclude)
            if "beacons.csv" in filenames and "floats.csv" in filenames and here not in found:
                rel = here.relative_to(root_abs).as_posix()
                found[here] = root_abs.name if rel == "." else rel
    by_name: dict[str, Path] = {}
    for path, name in found.items():
        if name in by_name:
            raise InputError(
                f"missions {by_name[name]} and {path} would both write OUT/{name}/; give roots whose "
                "missions have distinct relative paths"
            )
        by_name[name] = path

    missions = []
    for name, path in sorted(by_name.items()):
        csvs = sorted(p.stem for p in path.glob("*.csv") if p.name not in ("beacons.csv", "floats.csv"))
        try:
            frame = read_csv_table(path / "floats.csv", FLOAT_REQUIRED, FLOAT_OPTIONAL)
        except InputError as exc:
            rows = {fid: {} for fid in csvs} or {"(floats.csv)": {}}
            missions.append(Mission(path, name, rows, error=str(exc)))
            continue
        rows = {}
        for record in frame.to_dict("records"):
            rows.setdefault(str(record["float_id"]), {k: str(v) for k, v in record.items()})
        orphans = tuple(fid for fid in csvs if fid not in rows)
        missions.append(Mission(path, name, rows, orphans=orphans))
    for mission in missions:
        for float_id in mission.rows:
            if f"{mission.name}/{float_id}" in by_name:
                raise InputError(
                    f"mission {by_name[f'{mission.name}/{float_id}']} would write OUT/{mission.name}/{float_id}/, "
                    f"the output directory of float {float_id!r} of mission {mission.path}"
                )
    return missions


# --------------------------------------------------------------------------------------
# Planning


@dataclass(frozen=True)
class FloatTask:
    """Everything a worker needs to track one float and install its outputs (picklable)."""

    mission: str
    float_id: str
    float_path: Path
    out_dir: Path  # OUT/<mission>/<float_id>, the final location
    config_files: tuple[Path, ...]
    overrides: dict[str, dict[str, Any]]
    plots: bool
    key: str
    components: dict[str, Any]
    why: str  # why it is (re)processed: "new", "float file changed", "forced", ...
    lock_path: Path
    lock_token: str


@dataclass
class FloatOutcome:
    mission: str
    float_id: str
    status: str  # processed / skipped / failed
    reason: str = ""
    seconds: float | None = None
    warnings: int | None = None
    output: str = ""
    detail: str = ""  # traceback of an unexpected exception, for batch.log

    def row(self) -> dict[str, Any]:
        seconds = "" if self.seconds is None else f"{self.seconds:.2f}"
        warnings = "" if self.warnings is None else self.warnings
        return dict(
            mission=self.mission,
            float_id=self.float_id,
            status=self.status,
            reason=self.reason,
            seconds=seconds,
            warnings=warnings,
            output=self.output,
        )


_COMPONENT_NAMES = {
    "float_file_sha256": "float file changed",
    "beacons_sha256": "beacons.csv changed",
    "floats_row_sha256": "floats.csv row changed",
    "config_sha256": "config changed",
    "rafostrack_version": "package version changed",
    "plots": "plots option changed",
}


def _sha256_json(value: Any) -> str:
    return hashlib.sha256(json.dumps(value, sort_keys=True, default=str).encode()).hexdigest()


def read_manifest(out_dir: Path) -> dict[str, Any] | None:
    try:
        data = json.loads((out_dir / MANIFEST).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def _is_complete(out_dir: Path, manifest: dict[str, Any]) -> bool:
    files = manifest.get("files")
    if not isinstance(files, dict) or not files:
        return False
    for name, size in files.items():
        try:
            if (out_dir / name).stat().st_size != size:
                return False
        except OSError:
            return False
    return True


def _why(out_dir: Path, key: str, components: dict[str, Any], force: bool) -> str | None:
    """None when the outputs are complete and made from the same inputs; else the reason."""
    manifest = read_manifest(out_dir)
    if manifest is None:
        if out_dir.exists():
            return "no batch manifest (incomplete, or written by another command)"
        return "new"
    if manifest.get("key") != key:
        old = manifest.get("components") or {}
        changed = [text for name, text in _COMPONENT_NAMES.items() if old.get(name) != components.get(name)]
        return ", ".join(changed) or "inputs changed"
    if not _is_complete(out_dir, manifest):
        return "outputs incomplete (a file listed in the manifest is missing or changed)"
    return "forced" if force else None


def plan(
    missions: Sequence[Mission],
    out: Path,
    *,
    config_files: tuple[Path, ...] = (),
    overrides: dict[str, dict[str, Any]] | None = None,
    plots: bool = True,
    force: bool = False,
    lock_token: str = "",
) -> tuple[list[FloatTask], list[FloatOutcome]]:
    """Split every float into work to do (tasks) and outcomes known now (skipped, or failed
    before running: unreadable floats.csv, bad mission config, missing arrival file)."""
    from .pipeline import TrackInputs

    overrides = overrides or {}
    out = Path(out).resolve()
    tasks: list[FloatTask] = []
    known: list[FloatOutcome] = []
    for mission in missions:
        mission_out = out / mission.name
        try:
            beacons_sha = file_digest(mission.path / "beacons.csv")
        except OSError as exc:
            beacons_sha, beacons_error = "", f"{mission.path / 'beacons.csv'}: cannot read: {exc.strerror or exc}"
        else:
            beacons_error = ""
        for float_id, row in sorted(mission.rows.items()):
            float_path = mission.path / f"{float_id}.csv"
            out_dir = mission_out / float_id
            fail = _known_failure(mission, float_id, float_path, beacons_error)
            if fail is not None:
                status, reason = fail
                known.append(FloatOutcome(mission.name, float_id, status, reason))
                continue
            inputs = TrackInputs(float_path=float_path, config_files=tuple(config_files), overrides=overrides)
            try:
                config = load_config(inputs.config_layers(), inputs.overrides).to_dict()
                float_sha = file_digest(float_path)
            except InputError as exc:
                known.append(FloatOutcome(mission.name, float_id, FAILED, str(exc)))
                continue
            except OSError as exc:
                known.append(FloatOutcome(mission.name, float_id, FAILED, f"{float_path}: {exc.strerror or exc}"))
                continue
            components = {
                "float_file_sha256": float_sha,
                "beacons_sha256": beacons_sha,
                "floats_row_sha256": _sha256_json(row),
                "config_sha256": _sha256_json(config),
                "rafostrack_version": __version__,
                "plots": bool(plots),
            }
            key = _sha256_json({"format": MANIFEST_FORMAT, **components})
            why = _why(out_dir, key, components, force)
            if why is None:
                known.append(FloatOutcome(mission.name, float_id, SKIPPED, "unchanged", output=str(out_dir)))
                continue
            tasks.append(
                FloatTask(
                    mission=mission.name,
                    float_id=float_id,
                    float_path=float_path,
                    out_dir=out_dir,
                    config_files=tuple(config_files),
                    overrides=overrides,
                    plots=plots,
                    key=key,
                    components=components,
                    why=why,
                    lock_path=out / LOCK_NAME,
                    lock_token=lock_token,
                )
            )
    return tasks, known


def _known_failure(mission: Mission, float_id: str, float_path: Path, beacons_error: str) -> tuple[str, str] | None:
    if mission.error is not None:
        return FAILED, mission.error
    if beacons_error:
        return FAILED, beacons_error
    if float_id in ("", ".", "..") or float_id.startswith(".") or any(c in float_id for c in "/\\"):
        return FAILED, f"{mission.path / 'floats.csv'}: float_id {float_id!r} cannot name an output directory"
    if not float_path.is_file():
        # Listed but not (yet) there: e.g. a float not recovered yet. Not a failure.
        return SKIPPED, f"no arrival file {float_path.name} (listed in floats.csv)"
    return None


# --------------------------------------------------------------------------------------
# The per-float job (runs in a worker process, local or Dask)


def process_float(task: FloatTask) -> FloatOutcome:
    """Track one float into a temporary sibling directory, write its manifest last, then swap
    it into place. Never raises: a failure is returned as an outcome with a one-line reason."""
    from .pipeline import TrackInputs, track_float

    started = time.perf_counter()
    staging = task.out_dir.parent / f".{task.float_id}.tmp-{os.getpid()}"
    try:
        if staging.exists():
            shutil.rmtree(staging)
        inputs = TrackInputs(float_path=task.float_path, config_files=task.config_files, overrides=task.overrides)
        result = track_float(inputs, staging, plots=task.plots)
        built = Path(result.out_dir)
        files = {p.name: p.stat().st_size for p in sorted(built.iterdir()) if p.is_file()}
        manifest = {
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
        write_json(built / MANIFEST, manifest)  # last: its presence marks the directory complete
        _check_lock(task)
        _swap_into_place(built, task.out_dir)
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
            _one_line(exc),
            seconds=time.perf_counter() - started,
            detail=traceback.format_exc(),
        )
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def _one_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0]}" if text else type(exc).__name__


def _check_lock(task: FloatTask) -> None:
    """Refuse to install outputs when this run no longer holds the lock (it was killed and
    another run took over while this worker went on)."""
    if not task.lock_token:
        return
    holder = _read_lock(task.lock_path)
    if holder is None or holder.get("token") != task.lock_token:
        raise RuntimeError(f"{task.lock_path}: this batch run no longer holds the lock; outputs not installed")


def _swap_into_place(new: Path, final: Path) -> None:
    """Replace `final` by `new` with renames: old -> trash, new -> final, delete trash."""
    trash = final.parent / f".{final.name}.trash-{os.getpid()}"
    if trash.exists():
        shutil.rmtree(trash)
    if final.exists() or final.is_symlink():
        os.rename(final, trash)
    os.rename(new, final)
    if trash.is_dir() and not trash.is_symlink():
        shutil.rmtree(trash, ignore_errors=True)
    elif trash.exists() or trash.is_symlink():
        trash.unlink()


# --------------------------------------------------------------------------------------
# Execution


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
        ctx.set_forkserver_preload(["rafostrack.batch", "rafostrack.pipeline"])
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
                        yield _crashed(task, _one_line(exc), traceback.format_exc())
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
        raise InputError(f"--scheduler {address}: cannot connect to a Dask scheduler: {_one_line(exc)}") from None


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
            yield _crashed(task, f"Dask: {_one_line(exc)}", traceback.format_exc())


def _crashed(task: FloatTask, reason: str, detail: str = "") -> FloatOutcome:
    return FloatOutcome(task.mission, task.float_id, FAILED, reason, detail=detail)


# --------------------------------------------------------------------------------------
# Lock


class LockHeldError(InputError):
    """Another batch run holds OUT's lock (the CLI exits with code 2)."""


def _boot_id() -> str:
    try:
        return Path("/proc/sys/kernel/random/boot_id").read_text().strip()
    except OSError:
        return ""


def _proc_start(pid: int) -> str:
    """The process's start time in clock ticks since boot (Linux), to tell a reused pid."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return ""
    fields = stat[stat.rfind(")") + 2 :].split()
    return fields[19] if len(fields) > 19 else ""


def _read_lock(path: Path) -> dict[str, Any] | None:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def _holder_alive(holder: dict[str, Any]) -> bool | None:
    """True / False for a holder on this host; None when it runs elsewhere (cannot tell)."""
    if holder.get("host") != socket.gethostname():
        return None
    if holder.get("boot_id") and _boot_id() and holder["boot_id"] != _boot_id():
        return False  # the machine rebooted since
    try:
        pid = int(holder.get("pid"))
        os.kill(pid, 0)
    except (TypeError, ValueError, ProcessLookupError):
        return False
    except PermissionError:
        pass  # alive, another user's
    start = _proc_start(pid)
    return not (holder.get("proc_start") and start and start != holder["proc_start"])


def _describe(holder: dict[str, Any]) -> str:
    return f"pid {holder.get('pid')} on {holder.get('host')}, started {holder.get('started')}"


class BatchLock:
    """`OUT/.rafostrack-batch.lock`, created with O_CREAT|O_EXCL and holding pid, host and
    start time. A stale lock (its pid is gone on this host) is taken over; taking over is
    serialised by an flock on a guard file so that two runs cannot both take it over."""

    STALE_UNREADABLE_S = 60.0  # a lock file still empty after this long was left by a crash

    def __init__(self, out: Path, log: Callable[[str], None]):
        self.path = Path(out) / LOCK_NAME
        self.log = log
        self.token = uuid.uuid4().hex
        self.held = False

    def acquire(self) -> None:
        info = {
            "pid": os.getpid(),
            "host": socket.gethostname(),
            "started": datetime.now(UTC).isoformat(timespec="seconds"),
            "token": self.token,
            "boot_id": _boot_id(),
            "proc_start": _proc_start(os.getpid()),
        }
        for _ in range(5):
            try:
                fd = os.open(self.path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
            except FileExistsError:
                self._take_over_if_stale()
                continue
            with os.fdopen(fd, "w", encoding="utf-8") as fh:
                json.dump(info, fh)
                fh.flush()
                os.fsync(fh.fileno())
            self.held = True
            return
        raise LockHeldError(f"{self.path}: could not take the lock (it keeps changing); try again")

    def _take_over_if_stale(self) -> None:
        holder = _read_lock(self.path)
        if holder is None:
            try:
                age = time.time() - self.path.stat().st_mtime
            except FileNotFoundError:
                return  # released meanwhile: try again
            if age < self.STALE_UNREADABLE_S:
                raise LockHeldError(f"{self.path}: another batch run is starting to write to this output directory")
            reason = f"unreadable lock file, {age:.0f} s old"
        else:
            alive = _holder_alive(holder)
            if alive is None:
                raise LockHeldError(
                    f"{self.path}: another batch run ({_describe(holder)}) holds the lock on this output directory; "
                    "if that run is gone, delete the lock file"
                )
            if alive:
                raise LockHeldError(
                    f"{self.path}: another batch run ({_describe(holder)}) is writing to this output directory; "
                    "not starting"
                )
            reason = f"{_describe(holder)}, no longer running"
        import fcntl

        with open(self.path.with_name(LOCK_NAME + ".guard"), "a+") as guard:
            fcntl.flock(guard, fcntl.LOCK_EX)
            if _read_lock(self.path) == holder and self.path.exists():
                self.path.unlink()
                self.log(f"taking over a stale lock {self.path} ({reason})")

    def release(self) -> None:
        if self.held:
            holder = _read_lock(self.path)
            if holder is not None and holder.get("token") == self.token:
                self.path.unlink(missing_ok=True)
            self.held = False

    def __enter__(self) -> BatchLock:
        self.acquire()
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


def clean_stale(out: Path, missions: Iterable[Mission], log: Callable[[str], None]) -> None:
    """Remove temporary directories and files that a killed run left in OUT (under the lock,
    so no other batch run is writing there)."""
    places = [Path(out)] + [Path(out) / m.name for m in missions]
    for place in dict.fromkeys(places):
        try:
            entries = list(os.scandir(place))
        except OSError:
            continue
        for entry in entries:
            if entry.is_dir(follow_symlinks=False) and _STALE_DIR.match(entry.name):
                shutil.rmtree(entry.path, ignore_errors=True)
                log(f"removed {entry.path} (left by an interrupted run)")
            elif entry.is_file(follow_symlinks=False) and _STALE_FILE.match(entry.name):
                Path(entry.path).unlink(missing_ok=True)
                log(f"removed {entry.path} (left by an interrupted run)")


# --------------------------------------------------------------------------------------
# Reporting


class Reporter:
    """Progress and log lines. On a terminal: a bar redrawn in place with log lines above
    it; otherwise (cron) one plain line per event. Every line also goes to batch.log."""

    BAR = 28

    def __init__(self, stream: TextIO, tty: bool):
        self.stream = stream
        self.tty = tty
        self.lines: list[str] = []
        self.total = 0
        self.counts = {PROCESSED: 0, FAILED: 0}
        self.started = time.monotonic()
        self._bar_len = 0

    def log(self, message: str, console: bool = True) -> None:
        stamp = datetime.now(UTC).isoformat(timespec="seconds")
        self.lines.append(f"{stamp} {message}")
        if console:
            self._clear_bar()
            self.stream.write(f"rafostrack batch: {message}\n")
            self._draw_bar()
            self.stream.flush()

    def start(self, total: int) -> None:
        self.total = total
        self.started = time.monotonic()
        self._draw_bar()

    def done(self, outcome: FloatOutcome) -> None:
        self.counts[outcome.status] = self.counts.get(outcome.status, 0) + 1
        n = sum(self.counts.values())
        where = f"{outcome.mission}/{outcome.float_id}"
        if outcome.status == PROCESSED:
            took = f" in {outcome.seconds:.1f} s" if outcome.seconds is not None else ""
            warn = f", {outcome.warnings} input warning(s)" if outcome.warnings else ""
            message = f"[{n}/{self.total}] {where} processed{took} ({outcome.reason}{warn})"
        else:
            message = f"[{n}/{self.total}] {where} {outcome.status}: {outcome.reason}"
        # On a terminal only failures interrupt the bar; under cron every float gets a line.
        self.log(message, console=not self.tty or outcome.status == FAILED)
        if outcome.detail:
            self.lines.append(outcome.detail.rstrip())
        if self.tty:
            self._draw_bar()
            self.stream.flush()

    def finish(self) -> None:
        self._clear_bar()
        self.stream.flush()

    def _bar_text(self) -> str:
        n = sum(self.counts.values())
        filled = round(self.BAR * n / self.total) if self.total else self.BAR
        elapsed = time.monotonic() - self.started
        eta = f"  ~{(self.total - n) * elapsed / n:.0f} s left" if 0 < n < self.total else ""
        return (
            f"[{'#' * filled}{'.' * (self.BAR - filled)}] {n}/{self.total}  "
            f"processed {self.counts[PROCESSED]}  failed {self.counts[FAILED]}  {elapsed:.0f} s{eta}"
        )

    def _draw_bar(self) -> None:
        if self.tty and self.total:
            text = self._bar_text()
            self.stream.write("\r" + text + " " * max(0, self._bar_len - len(text)))
            self._bar_len = len(text)

    def _clear_bar(self) -> None:
        if self.tty and self._bar_len:
            self.stream.write("\r" + " " * self._bar_len + "\r")
            self._bar_len = 0


def summary_table(outcomes: Sequence[FloatOutcome], elapsed_s: float, out: Path) -> str:
    """The table printed at the end: every float processed or failed (skipped ones are
    counted; all are listed in batch-summary.csv), then the totals."""
    counts = {s: sum(o.status == s for o in outcomes) for s in (PROCESSED, SKIPPED, FAILED)}
    shown = [o for o in outcomes if o.status != SKIPPED or o.reason != "unchanged"]
    lines = []
    if shown:
        header = ("mission", "float_id", "status", "seconds", "reason")
        rows = [(o.mission, o.float_id, o.status, o.row()["seconds"], o.reason) for o in shown]
        widths = [max(len(str(r[i])) for r in [header, *rows]) for i in range(4)]
        for r in [header, *rows]:
            lines.append("  ".join(str(r[i]).ljust(widths[i]) for i in range(4)) + "  " + str(r[4]))
    unchanged = len(outcomes) - len(shown)
    lines.append(
        f"{len(outcomes)} floats: {counts[PROCESSED]} processed, {counts[SKIPPED]} skipped"
        f"{f' ({unchanged} unchanged)' if unchanged else ''}, {counts[FAILED]} failed in {elapsed_s:.1f} s"
    )
    lines.append(f"summary: {Path(out) / SUMMARY_NAME}  log: {Path(out) / LOG_NAME}")
    return "\n".join(lines)


def _summary_csv(outcomes: Sequence[FloatOutcome]) -> str:
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=SUMMARY_COLUMNS, lineterminator="\n")
    writer.writeheader()
    for outcome in outcomes:
        writer.writerow(outcome.row())
    return buf.getvalue()


# --------------------------------------------------------------------------------------
# The whole run


def default_jobs() -> int:
    """The cores this process may use (its CPU affinity where known, else all)."""
    try:
        return len(os.sched_getaffinity(0)) or 1
    except AttributeError:
        return os.cpu_count() or 1


@dataclass
class BatchResult:
    outcomes: list[FloatOutcome]
    exit_code: int  # 0 all good, 1 some floats failed
    summary: str  # the table to print

    def count(self, status: str) -> int:
        return sum(o.status == status for o in self.outcomes)


@dataclass(frozen=True)
class BatchOptions:
    roots: tuple[Path, ...]
    out: Path
    jobs: int
    force: bool
    scheduler: str | None
    config_files: tuple[Path, ...]
    overrides: dict[str, dict[str, Any]]
    plots: bool


def run_batch(
    roots: Sequence[Path],
    out: Path,
    *,
    jobs: int | None = None,
    force: bool = False,
    scheduler: str | None = None,
    config_file: Path | None = None,
    overrides: dict[str, dict[str, Any]] | None = None,
    plots: bool = True,
    stream: TextIO | None = None,
    tty: bool | None = None,
) -> BatchResult:
    """Discover, plan, run and report (see the module docstring). Usage problems (a bad root,
    no missions, a bad --config, an unreachable scheduler, OUT locked by another run) raise
    `InputError` before anything is written."""
    stream = stream if stream is not None else sys.stderr
    tty = tty if tty is not None else bool(getattr(stream, "isatty", lambda: False)())
    jobs = jobs if jobs is not None else default_jobs()
    if jobs < 1:
        raise InputError(f"--jobs must be >= 1, got {jobs}")
    options = BatchOptions(
        roots=tuple(Path(r) for r in roots),
        out=Path(out),
        jobs=jobs,
        force=force,
        scheduler=scheduler,
        config_files=(Path(config_file).resolve(),) if config_file is not None else (),
        overrides=overrides or {},
        plots=plots,
    )
    load_config(options.config_files, options.overrides)  # a bad --config or flag: exit 2
    missions = discover(options.roots, exclude=options.out)
    if not missions:
        raise InputError(
            f"no mission directories under {', '.join(map(str, roots))} "
            "(a mission directory holds beacons.csv, floats.csv and <float_id>.csv files)"
        )
    client = dask_client(scheduler) if scheduler else None
    try:
        options.out.mkdir(parents=True, exist_ok=True)
        reporter = Reporter(stream, tty)
        with BatchLock(options.out, reporter.log) as lock:
            outcomes, table = _run_locked(options, missions, lock, reporter, client)
    finally:
        if client is not None:
            client.close()
    exit_code = 1 if any(o.status == FAILED for o in outcomes) else 0
    return BatchResult(outcomes, exit_code, table)


def _run_locked(
    options: BatchOptions, missions: list[Mission], lock: BatchLock, reporter: Reporter, client: Any
) -> tuple[list[FloatOutcome], str]:
    """Everything done while holding OUT's lock: clean, plan, run, write the reports."""
    from .io.atomic import write_text_atomic

    started = time.monotonic()
    out = options.out
    reporter.log(
        f"rafostrack {__version__}, pid {os.getpid()} on {socket.gethostname()}; "
        f"roots: {' '.join(map(str, options.roots))}; out: {out}",
        console=False,
    )
    clean_stale(out, missions, reporter.log)
    for mission in missions:
        if mission.orphans:
            names = ", ".join(f"{f}.csv" for f in mission.orphans)
            reporter.log(f"{mission.name}: ignoring {names} (no row in floats.csv)", console=False)
    tasks, known = plan(
        missions,
        out,
        config_files=options.config_files,
        overrides=options.overrides,
        plots=options.plots,
        force=options.force,
        lock_token=lock.token,
    )
    skipped = sum(o.status == SKIPPED for o in known)
    if client is not None:
        where = f"on Dask scheduler {options.scheduler}"
    else:
        where = f"with {min(options.jobs, max(len(tasks), 1))} local worker process(es)"
    reporter.log(
        f"{len(tasks) + len(known)} floats in {len(missions)} mission(s): {len(tasks)} to process {where}, "
        f"{skipped} skipped, {len(known) - skipped} failed before running"
    )
    for outcome in known:
        line = f"{outcome.mission}/{outcome.float_id} {outcome.status}: {outcome.reason}"
        reporter.log(line, console=outcome.status == FAILED)
    reporter.start(len(tasks))
    outcomes = list(known)
    try:
        runner = run_dask(tasks, client) if client is not None else run_local(tasks, options.jobs)
        for outcome in runner:
            outcomes.append(outcome)
            reporter.done(outcome)
    finally:
        reporter.finish()
    outcomes.sort(key=lambda o: (o.mission, o.float_id))
    table = summary_table(outcomes, time.monotonic() - started, out)
    reporter.lines.extend(table.splitlines())
    write_text_atomic(out / SUMMARY_NAME, _summary_csv(outcomes))
    write_text_atomic(out / LOG_NAME, "\n".join(reporter.lines) + "\n")
    return outcomes, table
