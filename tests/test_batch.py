"""`rafostrack batch`: discovery, incremental planning, failures, kill safety, locking, and
identical outputs whatever the parallelism (local processes or a Dask cluster).

The tree: 2 simulated missions (`m1`, `deep/m2`) x 3 floats of 12 days, 150 particles
(`[filter] particles` in each mission's rafostrack.toml), no plots.
"""

from __future__ import annotations

import csv
import dataclasses
import fcntl
import io
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner
from support import parquet_bytes, timing_free

from rafostrack import batch as b
from rafostrack.cli import main
from rafostrack.config import default_layer, load_config
from rafostrack.sim.mission_writer import write_mission
from rafostrack.sim.scenarios import synthetic_scenario
from rafostrack.sim.simulate import simulate_mission

MISSIONS = ("deep/m2", "m1")
FLOATS = [(m, f"sim{i}") for m in MISSIONS for i in (1, 2, 3)]


def _make_tree(root: Path) -> Path:
    for i, name in enumerate(MISSIONS):
        rng = np.random.default_rng(100 + i)
        beacons, floats = synthetic_scenario(days=12, n_floats=3, rng=rng)
        mission = simulate_mission(beacons, floats, load_config().model, rng)
        write_mission(mission, root / name, {"filter": {"particles": 150}})
    return root


@pytest.fixture(scope="module")
def tree(tmp_path_factory) -> Path:
    return _make_tree(tmp_path_factory.mktemp("tree") / "archive")


@pytest.fixture(scope="module")
def baseline(tree, tmp_path_factory) -> Path:
    """The tree processed once with --jobs 1: the reference outputs."""
    out = tmp_path_factory.mktemp("baseline")
    result = _batch(tree, out, "--jobs", "1")
    assert result.exit_code == 0, result.output
    return out


@pytest.fixture
def work_tree(tree, tmp_path) -> Path:
    """A private copy of the tree, for tests that change inputs."""
    return Path(shutil.copytree(tree, tmp_path / "archive"))


def _batch(root: Path, out: Path, *args: str):
    return CliRunner().invoke(main, ["batch", str(root), "--out", str(out), "--no-plots", *args])


def _summary(out: Path) -> dict[tuple[str, str], dict[str, str]]:
    with open(out / "batch-summary.csv", newline="") as fh:
        return {(r["mission"], r["float_id"]): r for r in csv.DictReader(fh)}


def _statuses(out: Path) -> dict[str, set[tuple[str, str]]]:
    by: dict[str, set[tuple[str, str]]] = {"processed": set(), "skipped": set(), "failed": set()}
    for key, row in _summary(out).items():
        by[row["status"]].add(key)
    return by


def _complete(out: Path) -> set[tuple[str, str]]:
    return {(m, f) for m, f in FLOATS if (out / m / f / b.MANIFEST).is_file()}


def _lock_is_free(out: Path) -> bool:
    """Whether OUT's lock can be taken now (an flock of our own, independent of filelock)."""
    with open(out / b.LOCK_NAME, "a") as fh:
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            return False
        fcntl.flock(fh, fcntl.LOCK_UN)
        return True


def _parquet_bytes(out: Path) -> dict[str, bytes]:
    return {str(p.relative_to(out)): p.read_bytes() for p in sorted(out.rglob("*.parquet"))}


def _exe() -> str:
    exe = shutil.which("rafostrack", path=str(Path(sys.executable).parent))
    assert exe is not None
    return exe


def _slow_config(tmp_path: Path) -> Path:
    """More particles, so that a float takes long enough to be caught mid-run."""
    cfg = tmp_path / "slow.toml"
    cfg.write_text("[filter]\nparticles = 1000\n")
    return cfg


def _start(args: list[str], logs: Path) -> subprocess.Popen:
    """`rafostrack ARGS` in the background, its output to files (not pipes: nothing can block)."""
    with open(logs.with_suffix(".out"), "w") as out, open(logs.with_suffix(".err"), "w") as err:
        return subprocess.Popen([_exe(), *args], stdout=out, stderr=err, stdin=subprocess.DEVNULL)


def _wait_for(predicate, timeout: float, what: str, proc: subprocess.Popen | None = None) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if proc is not None and proc.poll() is not None:
            pytest.fail(f"batch ended (code {proc.returncode}) before {what}")
        if time.monotonic() > deadline:
            pytest.fail(f"timed out waiting for {what}")
        time.sleep(0.005)


# --------------------------------------------------------------------------------------


def test_discovery_mirrors_the_tree(tree, baseline):
    missions = b.discover([tree])
    assert [m.name for m in missions] == list(MISSIONS)  # truth/ subdirectories are not missions
    assert all(sorted(m.rows) == ["sim1", "sim2", "sim3"] for m in missions)
    assert _complete(baseline) == set(FLOATS)
    for m, f in FLOATS:
        names = {p.name for p in (baseline / m / f).iterdir()}
        assert {"track.parquet", "labels.parquet", "run.json", b.MANIFEST} <= names
    assert not list(baseline.rglob(".*tmp*")) and not (baseline / b.LOCK_INFO_NAME).exists()
    assert _lock_is_free(baseline)
    assert (baseline / "batch.log").read_text().count("processed") >= 6


def test_incremental_reprocesses_exactly_what_changed(work_tree, tmp_path):
    out = tmp_path / "out"
    result = _batch(work_tree, out)
    assert result.exit_code == 0, result.output
    assert _statuses(out)["processed"] == set(FLOATS)

    result = _batch(work_tree, out)
    assert result.exit_code == 0, result.output
    assert _statuses(out)["skipped"] == set(FLOATS)
    assert "6 skipped" in result.output

    # One float file changes (a duplicated row: same data, other bytes): that float only.
    float_file = work_tree / "m1" / "sim2.csv"
    lines = float_file.read_text().splitlines(keepends=True)
    float_file.write_text("".join([*lines, lines[-1]]))
    result = _batch(work_tree, out)
    assert result.exit_code == 0, result.output
    summary = _summary(out)
    assert _statuses(out)["processed"] == {("m1", "sim2")}
    assert summary["m1", "sim2"]["reason"] == "float file changed"

    # beacons.csv changes (rows reordered): its whole mission, not the other one.
    beacons = work_tree / "deep" / "m2" / "beacons.csv"
    header, first, second, *rest = beacons.read_text().splitlines(keepends=True)
    beacons.write_text("".join([header, second, first, *rest]))
    result = _batch(work_tree, out)
    assert result.exit_code == 0, result.output
    assert _statuses(out)["processed"] == {("deep/m2", f) for f in ("sim1", "sim2", "sim3")}
    assert _summary(out)["deep/m2", "sim1"]["reason"] == "beacons.csv changed"

    # One row of floats.csv changes: that float only, although the file's bytes changed.
    floats = work_tree / "m1" / "floats.csv"
    rows = list(csv.reader(floats.read_text().splitlines()))
    col = rows[0].index("window_s")
    row = next(r for r in rows if r[0] == "sim3")
    row[col] = row[col] + ".0"
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerows(rows)
    floats.write_text(buf.getvalue())
    result = _batch(work_tree, out)
    assert result.exit_code == 0, result.output
    assert _statuses(out)["processed"] == {("m1", "sim3")}
    assert _summary(out)["m1", "sim3"]["reason"] == "floats.csv row changed"

    # The effective config changes (a flag): every float; --force redoes everything.
    result = _batch(work_tree, out, "--likelihood", "unranked")
    assert result.exit_code == 0, result.output
    assert _statuses(out)["processed"] == set(FLOATS)
    assert _summary(out)["m1", "sim1"]["reason"] == "config changed"
    result = _batch(work_tree, out, "--likelihood", "unranked", "--force", "--jobs", "2")
    assert result.exit_code == 0, result.output
    assert _statuses(out)["processed"] == set(FLOATS)
    assert _summary(out)["m1", "sim1"]["reason"] == "forced"


def test_default_valued_key_in_mission_config_retracks_the_float(tmp_path):
    """A key the user sets is kept as set, not calibrated: writing the default sound speed
    into a mission's rafostrack.toml changes the track, so the float is tracked again."""
    default = default_layer()["model"]["sound_speed_m_s"]
    assert default == load_config().model.sound_speed_m_s == 1480.0
    rng = np.random.default_rng(100)
    beacons, floats = synthetic_scenario(days=30, n_floats=1, rng=rng)  # enough arrivals to calibrate
    write_mission(simulate_mission(beacons, floats, load_config().model, rng), tmp_path / "archive" / "m")
    toml = tmp_path / "archive" / "m" / "rafostrack.toml"
    toml.write_text("[filter]\nparticles = 150\n")  # the simulated model is the default one: no [model]
    out = tmp_path / "out"
    result = _batch(tmp_path / "archive", out)
    assert result.exit_code == 0, result.output
    assert _statuses(out)["processed"] == {("m", "sim1")}
    first = (out / "m" / "sim1" / "track.parquet").read_bytes()

    toml.write_text(toml.read_text() + f"[model]\nsound_speed_m_s = {default}\n")
    result = _batch(tmp_path / "archive", out)
    assert result.exit_code == 0, result.output
    assert _statuses(out)["processed"] == {("m", "sim1")}
    assert _summary(out)["m", "sim1"]["reason"] == "config changed"
    assert (out / "m" / "sim1" / "track.parquet").read_bytes() != first  # the sound speed held, not fitted


def test_a_corrupt_float_fails_alone(work_tree, tmp_path):
    (work_tree / "m1" / "sim2.csv").write_text("time,toa_s\n2010-01-01T00:00:00Z,12.5\n2010-01-02T00:00:00Z,abc\n")
    (work_tree / "deep" / "m2" / "sim4.csv").write_text("time,toa_s\n")  # not in floats.csv: ignored
    out = tmp_path / "out"
    result = _batch(work_tree, out, "--jobs", "2")
    assert result.exit_code == 1, result.output
    statuses = _statuses(out)
    assert statuses["failed"] == {("m1", "sim2")}
    assert statuses["processed"] == set(FLOATS) - {("m1", "sim2")}
    reason = _summary(out)["m1", "sim2"]["reason"]
    assert "sim2.csv: line 3: field 'toa_s'" in reason and "abc" in reason
    assert reason in result.output  # in the printed table too
    assert "Traceback" not in result.output
    assert not (out / "m1" / "sim2").exists()
    assert "sim4.csv (no row in floats.csv)" in (out / "batch.log").read_text()


def test_an_unreadable_floats_table_fails_its_mission_only(work_tree, tmp_path):
    (work_tree / "m1" / "floats.csv").write_text("float;launch\n")
    out = tmp_path / "out"
    result = _batch(work_tree, out)
    assert result.exit_code == 1, result.output
    statuses = _statuses(out)
    assert statuses["failed"] == {("m1", f) for f in ("sim1", "sim2", "sim3")}
    assert statuses["processed"] == {("deep/m2", f) for f in ("sim1", "sim2", "sim3")}
    assert "separated by ';'" in _summary(out)["m1", "sim1"]["reason"]


@pytest.mark.reliability
def test_jobs_2_and_track_give_the_same_outputs_as_jobs_1(tree, baseline, tmp_path):
    """`batch --jobs 2` writes the Parquet bytes and (timings aside) the run.json of `--jobs 1`,
    and `rafostrack track` on one float the Parquet bytes of the batch."""
    out = tmp_path / "out"
    result = _batch(tree, out, "--jobs", "2")
    assert result.exit_code == 0, result.output
    ours, ref = _parquet_bytes(out), _parquet_bytes(baseline)
    assert len(ref) >= 12 and ours.keys() == ref.keys()
    assert all(ours[k] == ref[k] for k in ref)
    for mission, fid in FLOATS:
        run_1, run_2 = (json.loads((d / mission / fid / "run.json").read_text()) for d in (baseline, out))
        assert timing_free(run_1) == timing_free(run_2)
    args = ["track", str(tree / "m1" / "sim2.csv"), "--out", str(tmp_path / "t"), "--no-plots"]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    assert parquet_bytes(tmp_path / "t" / "sim2") == parquet_bytes(out / "m1" / "sim2")


@pytest.mark.slow
def test_dask_gives_the_same_bytes_as_local(tree, baseline, tmp_path):
    distributed = pytest.importorskip("distributed")
    out = tmp_path / "out"
    with distributed.LocalCluster(n_workers=2, processes=True, threads_per_worker=1, dashboard_address=None) as cluster:
        result = _batch(tree, out, "--scheduler", cluster.scheduler_address)
    assert result.exit_code == 0, result.output
    assert "Dask scheduler" in (out / "batch.log").read_text()
    assert _statuses(out)["processed"] == set(FLOATS)
    ours, ref = _parquet_bytes(out), _parquet_bytes(baseline)
    assert ours.keys() == ref.keys()
    assert all(ours[k] == ref[k] for k in ref)


def test_local_workers_run_math_libraries_single_threaded(monkeypatch):
    """BLAS results depend on the thread count: every worker uses one, whatever --jobs."""
    monkeypatch.delenv("OPENBLAS_NUM_THREADS", raising=False)
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    names = ["OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS"] * 2
    assert list(b.run_local(names, 2, fn=os.getenv)) == ["1"] * 4
    assert "OPENBLAS_NUM_THREADS" not in os.environ  # the batch process itself is left alone


def test_a_worker_never_installs_a_float_once_its_run_lost_the_lock(tree, tmp_path):
    """A worker still going after its run was killed and another run took the lock (a Dask
    worker, say) leaves OUT as the new run made it."""
    out = tmp_path / "out"
    (out / "m1").mkdir(parents=True)
    missions = [m for m in b.discover([tree]) if m.name == "m1"]
    tasks, _ = b.plan(missions, out, overrides={"filter": {"particles": 50}}, plots=False, run_id="killed-run")
    task = next(t for t in tasks if t.float_id == "sim1")
    (out / b.LOCK_INFO_NAME).write_text(json.dumps({"pid": 1, "host": "h", "started": "s", "run_id": "new-run"}))
    outcome = b.process_float(task)
    assert outcome.status == b.FAILED and "no longer holds the lock" in outcome.reason
    assert sorted(p.name for p in (out / "m1").iterdir()) == []  # nothing installed, nothing left aside

    # The same task while its run holds the lock is installed (the check above can fail).
    (out / b.LOCK_INFO_NAME).write_text(json.dumps({"pid": 1, "host": "h", "started": "s", "run_id": "killed-run"}))
    assert b.process_float(task).status == b.PROCESSED
    assert sorted(p.name for p in (out / "m1").iterdir()) == ["sim1"] and (out / "m1" / "sim1" / b.MANIFEST).is_file()


def test_a_worker_with_another_rafostrack_version_writes_nothing(tree, tmp_path):
    """Outputs are byte-identical between workers running the same installation; a worker
    running another version (a Dask worker, say) fails the float instead of writing outputs
    that the manifest would attribute to the batch process's version."""
    out = tmp_path / "out"
    missions = [m for m in b.discover([tree]) if m.name == "m1"]
    tasks, _ = b.plan(missions, out, plots=False)
    task = next(t for t in tasks if t.float_id == "sim1")
    other = dataclasses.replace(task, components={**task.components, "rafostrack_version": "0.0.1"})
    outcome = b.process_float(other)
    assert outcome.status == b.FAILED and "the batch process 0.0.1" in outcome.reason
    assert not out.exists()


@pytest.mark.slow
def test_sigkill_leaves_no_partial_output_and_a_rerun_finishes(work_tree, tmp_path):
    out = tmp_path / "out"
    cfg = _slow_config(tmp_path)
    args = ["batch", str(work_tree), "--out", str(out), "--jobs", "1", "--no-plots", "--config", str(cfg)]
    proc = _start(args, tmp_path / "killed")
    try:
        _wait_for(lambda: len(_complete(out)) >= 1, 60, "a first complete float", proc)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    time.sleep(0.3)  # its worker dies with it (it watches a pipe from the batch process)
    done = _complete(out)
    assert 1 <= len(done) < len(FLOATS), "the run was not caught mid-way"
    assert (out / b.LOCK_INFO_NAME).exists()  # left behind by the killed run ...
    assert _lock_is_free(out)  # ... but the kernel released its lock: nothing blocks the next run

    for path in out.rglob("*.parquet"):  # everything written so far reads back in full
        pq.read_table(path)
    visible = {(m, p.name) for m in MISSIONS if (out / m).is_dir() for p in (out / m).iterdir()}
    visible = {v for v in visible if not v[1].startswith(".")}
    assert visible == done  # no float directory is visible before it is complete

    result = CliRunner().invoke(
        main, ["batch", str(work_tree), "--out", str(out), "--no-plots", "--config", str(cfg), "--jobs", "2"]
    )
    assert result.exit_code == 0, result.output
    assert "did not finish; its lock was released when it ended" in result.output
    statuses = _statuses(out)
    assert statuses["skipped"] == done
    assert statuses["processed"] == set(FLOATS) - done
    assert _complete(out) == set(FLOATS)
    assert not [p for p in out.rglob(".*") if p.name != b.LOCK_NAME]
    for path in out.rglob("*.parquet"):
        pq.read_table(path)


@pytest.mark.slow
def test_sigkill_leaves_batch_log_with_a_line_per_finished_float(work_tree, tmp_path):
    """batch.log was written only at the end: a killed run left none. It grows as the run
    goes: its start line, then one whole line per float finished before the kill."""
    out = tmp_path / "out"
    cfg = _slow_config(tmp_path)
    args = ["batch", str(work_tree), "--out", str(out), "--jobs", "1", "--no-plots", "--config", str(cfg)]
    proc = _start(args, tmp_path / "killed")

    def processed() -> list[str]:
        text = (out / b.LOG_NAME).read_text() if (out / b.LOG_NAME).exists() else ""
        return [line for line in text.splitlines() if " processed in " in line]

    try:
        _wait_for(lambda: len(processed()) >= 2, 120, "two floats' lines in batch.log", proc)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    text = (out / b.LOG_NAME).read_text()
    assert text.endswith("\n") and f"pid {proc.pid} on " in text.splitlines()[0]
    logged = [tuple(line.split("] ", 1)[1].split(" processed")[0].rsplit("/", 1)) for line in processed()]
    assert len(set(logged)) == len(logged) >= 2 and set(logged) <= _complete(out) != set(FLOATS)
    assert len(_complete(out) - set(logged)) <= 1  # at most the one float finished as the run was killed


def test_batch_log_lines_are_written_as_they_come(tmp_path):
    """`Reporter.log_file`: the lines before it, then each line as it is logged; the file
    holds the run's lines only (a previous run's are replaced), whole."""
    path = tmp_path / "batch.log"
    path.write_text("a previous run's line\n")
    reporter = b.Reporter(io.StringIO(), tty=False)
    reporter.log("before the lock")
    with reporter.log_file(path):
        assert path.read_text().endswith(" before the lock\n")
        reporter.done(b.FloatOutcome("m1", "sim1", b.PROCESSED, "new", seconds=1.0, warnings=0))
        assert path.read_text().splitlines()[-1].endswith(" [1/0] m1/sim1 processed in 1.0 s (new)")
        reporter.lines.extend(["table line 1", "table line 2"])
    reporter.log("after the run")
    assert path.read_text() == "\n".join(reporter.lines[:-1]) + "\n" and len(reporter.lines) == 5


@pytest.mark.slow
def test_a_second_concurrent_run_does_not_write(work_tree, tmp_path):
    out = tmp_path / "out"
    cfg = _slow_config(tmp_path)
    args = ["batch", str(work_tree), "--out", str(out), "--no-plots", "--config", str(cfg)]
    first = _start(args, tmp_path / "first")
    try:
        _wait_for(lambda: (out / b.LOCK_INFO_NAME).is_file(), 60, "the first run's lock", first)
        second = _batch(work_tree, out, "--config", str(cfg))
        assert first.poll() is None, "the first run ended too soon for this test"
        assert second.exit_code == 2, second.output
        holder = json.loads((out / b.LOCK_INFO_NAME).read_text())
        assert "another batch run" in second.output
        assert f"pid {first.pid} on {socket.gethostname()}, started {holder['started']}" in second.output
        assert not (out / "batch-summary.csv").exists()  # the second run wrote nothing
        first.wait(timeout=120)
    finally:
        if first.poll() is None:
            first.kill()
    assert first.returncode == 0, (tmp_path / "first.err").read_text()
    assert "6 processed" in (tmp_path / "first.out").read_text()
    assert _complete(out) == set(FLOATS) and not (out / b.LOCK_INFO_NAME).exists() and _lock_is_free(out)


def test_a_killed_runs_lock_and_temporaries_are_cleaned(tree, baseline, tmp_path):
    """What a killed run leaves: its lock info, temporaries; and a lock file in the format of
    the hand-written lock of earlier versions, which no longer means anything."""
    out = Path(shutil.copytree(baseline, tmp_path / "out"))
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    lock = {"pid": dead.pid, "host": socket.gethostname(), "started": "2020-01-01T00:00:00+00:00"}
    (out / b.LOCK_NAME).write_text(json.dumps(lock))
    (out / b.LOCK_INFO_NAME).write_text(json.dumps({**lock, "run_id": "0" * 32}))
    (out / "m1" / ".sim1.tmp-123").mkdir()
    (out / "m1" / ".sim1.tmp-123" / "track.parquet").write_bytes(b"PAR1 truncated")
    (out / "deep" / "m2" / ".sim3.trash-77").mkdir()
    (out / ".batch.log.x1y2.tmp").write_text("partial")
    result = _batch(tree, out)
    assert result.exit_code == 0, result.output
    assert f"previous batch run on this output directory (pid {dead.pid} on {socket.gethostname()}" in result.output
    assert not (out / "m1" / ".sim1.tmp-123").exists() and not (out / "deep" / "m2" / ".sim3.trash-77").exists()
    assert not (out / ".batch.log.x1y2.tmp").exists()
    assert _statuses(out)["skipped"] == set(FLOATS)  # outputs are relocatable: paths are not hashed
    assert not (out / b.LOCK_INFO_NAME).exists() and _lock_is_free(out)


def test_a_held_lock_is_respected(tree, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    me = {"pid": os.getpid(), "host": socket.gethostname(), "started": "2030-01-01T00:00:00+00:00", "run_id": "x"}
    (out / b.LOCK_INFO_NAME).write_text(json.dumps(me))
    with open(out / b.LOCK_NAME, "a") as held:
        fcntl.flock(held, fcntl.LOCK_EX | fcntl.LOCK_NB)  # as another run holds it
        result = _batch(tree, out)
    assert result.exit_code == 2
    assert "another batch run" in result.output and "not starting" in result.output
    assert f"pid {os.getpid()} on {socket.gethostname()}, started 2030-01-01T00:00:00+00:00" in result.output
    assert json.loads((out / b.LOCK_INFO_NAME).read_text()) == me  # untouched
    assert sorted(p.name for p in out.iterdir()) == [b.LOCK_NAME, b.LOCK_INFO_NAME]


@pytest.mark.parametrize(
    ("make", "needle"),
    [
        (lambda p: p, "no mission directories under"),
        (lambda p: p / "missing", "missing: does not exist; expected a directory holding missions"),
        (lambda p: _a_file(p / "f.csv"), "f.csv: not a directory (expected a directory holding missions)"),
    ],
)
def test_usage_errors_exit_2(tmp_path, make, needle):
    """`batch /nonexistent` said "not a directory"; it says it does not exist."""
    result = _batch(make(tmp_path), tmp_path / "out")
    assert result.exit_code == 2
    assert needle in result.output and "Traceback" not in result.output


def _a_file(path: Path) -> Path:
    path.write_text("x\n")
    return path


def test_a_run_that_skips_every_float_starts_no_worker(tree, baseline, tmp_path):
    """A skip-only batch under --jobs 2 reported "with 1 local worker process(es)"."""
    out = Path(shutil.copytree(baseline, tmp_path / "out"))
    result = _batch(tree, out, "--jobs", "2")
    assert result.exit_code == 0, result.output
    assert "6 floats in 2 mission(s): 0 to process, 6 skipped, 0 failed before running" in result.output
    assert "worker" not in result.output


def test_bad_config_and_jobs_are_usage_errors(tree, tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[filter]\nparticels = 3\n")
    result = _batch(tree, tmp_path / "out", "--config", str(bad))
    assert result.exit_code == 2 and "did you mean 'particles'" in result.output
    result = _batch(tree, tmp_path / "out", "--jobs", "0")
    assert result.exit_code == 2
    assert not (tmp_path / "out").exists()


def test_progress_bar_on_a_terminal_and_lines_otherwise():
    outcomes = [
        b.FloatOutcome("m1", "sim1", b.PROCESSED, "new", seconds=1.0, warnings=0),
        b.FloatOutcome("m1", "sim2", b.FAILED, "sim2.csv: line 3: bad"),
    ]
    tty, plain = io.StringIO(), io.StringIO()
    for stream, is_tty in ((tty, True), (plain, False)):
        reporter = b.Reporter(stream, tty=is_tty)
        reporter.start(2)
        for outcome in outcomes:
            reporter.done(outcome)
        reporter.finish()
    assert "\r" in tty.getvalue() and "2/2" in tty.getvalue()
    assert "m1/sim2 failed: sim2.csv: line 3: bad\n" in tty.getvalue()
    assert "\r" not in plain.getvalue()
    assert plain.getvalue().splitlines() == [
        "rafostrack batch: [1/2] m1/sim1 processed in 1.0 s (new)",
        "rafostrack batch: [2/2] m1/sim2 failed: sim2.csv: line 3: bad",
    ]


def test_each_round_counts_its_own_floats():
    """A batch's second round (the mission's array) numbers its floats from 1 again."""
    stream = io.StringIO()
    reporter = b.Reporter(stream, tty=False)
    for total in (3, 2):
        reporter.start(total)
        for k in range(total):
            reporter.done(b.FloatOutcome("m", f"f{k}", b.PROCESSED, "new", seconds=1.0))
        reporter.finish()
    lines = [line for line in stream.getvalue().splitlines() if "] m/" in line]
    assert [line.split("]")[0].split("[")[1] for line in lines] == ["1/3", "2/3", "3/3", "1/2", "2/2"]
