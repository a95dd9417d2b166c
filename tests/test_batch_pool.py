"""`rafostrack.batch.pool`: local workers import the batch process's own rafostrack whatever
the current directory holds, and a worker that cannot start says why, in batch.log and the
summary ("cron breaks batch").

Each test runs the installed `rafostrack` entry point as a subprocess, as cron does, on a
tiny simulated mission (2 floats of 6 days, 50 particles, no plots).
"""

from __future__ import annotations

import csv
import os
import re
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from rafostrack.config import load_config
from rafostrack.sim.mission_writer import write_mission
from rafostrack.sim.scenarios import synthetic_scenario
from rafostrack.sim.simulate import simulate_mission

FLOAT_IDS = ("sim1", "sim2")


@pytest.fixture(scope="module")
def archive(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("archive")
    rng = np.random.default_rng(14)
    beacons, floats = synthetic_scenario(days=6, n_floats=len(FLOAT_IDS), rng=rng)
    write_mission(
        simulate_mission(beacons, floats, load_config().model, rng), root / "m", {"filter": {"particles": 50}}
    )
    return root


def _batch_from(cwd: Path, archive: Path, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    exe = shutil.which("rafostrack", path=str(Path(sys.executable).parent))
    assert exe is not None
    args = [exe, "batch", str(archive), "--out", "o", "--no-plots", "--jobs", "2"]
    return subprocess.run(args, cwd=cwd, env=env, capture_output=True, text=True, timeout=300, check=False)


def _summary(out: Path) -> dict[str, dict[str, str]]:
    with open(out / "batch-summary.csv", newline="") as fh:
        return {row["float_id"]: row for row in csv.DictReader(fh)}


@pytest.mark.slow
@pytest.mark.parametrize(
    "package_init",
    [None, "answer = 42  # an unrelated package that happens to be called rafostrack\n"],
    ids=["folder-named-rafostrack", "unrelated-rafostrack-package"],
)
def test_batch_runs_from_a_directory_holding_a_folder_named_rafostrack(archive, tmp_path, package_init):
    """`cd ~ && ~/rafostrack/.venv/bin/rafostrack batch ...` with the clone at ~/rafostrack."""
    (tmp_path / "rafostrack").mkdir()
    if package_init is not None:
        (tmp_path / "rafostrack" / "__init__.py").write_text(package_init)
    proc = _batch_from(tmp_path, archive)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    summary = _summary(tmp_path / "o")
    assert sorted(summary) == list(FLOAT_IDS)
    assert all(row["status"] == "processed" for row in summary.values()), summary
    assert "Traceback" not in proc.stderr


def test_a_worker_that_cannot_start_says_why_in_the_log_and_the_summary(archive, tmp_path):
    """Whatever breaks a worker's start-up (here: a sitecustomize that shadows rafostrack in
    the worker processes only), every float fails with the worker's real one-line cause in
    batch-summary.csv, the printed table and batch.log, which also holds the traceback."""
    shadow = tmp_path / "shadow"
    (shadow / "rafostrack").mkdir(parents=True)
    (shadow / "rafostrack" / "__init__.py").write_text("")
    site = tmp_path / "site"
    site.mkdir()
    (site / "sitecustomize.py").write_text(
        textwrap.dedent(
            f"""
            import sys
            if sys.argv[:1] == ["-c"]:  # multiprocessing's helper processes, not the batch process
                sys.path.insert(0, {str(shadow)!r})
            """
        )
    )
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(site), os.environ.get("PYTHONPATH")]))}
    work = tmp_path / "work"
    work.mkdir()
    proc = _batch_from(work, archive, env)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    summary = _summary(work / "o")
    assert sorted(summary) == list(FLOAT_IDS)
    reasons = {row["reason"] for row in summary.values()}
    assert {row["status"] for row in summary.values()} == {"failed"} and len(reasons) == 1, summary
    reason = reasons.pop()
    # The shadow package lacks what the worker imports: `__version__` (editable install) or
    # `rafostrack.cli` (regular install). Either way the worker's own error, on one line.
    pattern = r"a worker process cannot start: ((?:ImportError|ModuleNotFoundError): .*'rafostrack.*)"
    cause = re.fullmatch(pattern, reason)
    assert cause is not None, reason
    assert "shadow" in reason or "rafostrack.cli" in reason
    assert reason in proc.stdout  # the table
    log = (work / "o" / "batch.log").read_text()
    assert f"m/sim1 failed: {reason}" in log and f"m/sim2 failed: {reason}" in log
    assert "worker stderr: Traceback (most recent call last):" in log
    assert f"worker stderr: {cause.group(1)}" in log


def _rebuild_in_the_batch_process_only(batch_pid: int) -> str:
    if os.getpid() != batch_pid:
        raise RuntimeError("this task cannot be rebuilt in a worker")
    return "task"


class _TaskThatKillsItsWorker:
    """Unpickling it in a worker raises where the pool does not catch it: the worker dies
    after it has started, with a traceback on its stderr."""

    mission, float_id = "m", "f1"  # what run_local reports a failed task by

    def __reduce__(self):
        return (_rebuild_in_the_batch_process_only, (os.getpid(),))


def test_a_worker_dying_after_start_up_fails_its_float_with_its_last_error():
    from rafostrack.batch import FAILED, run_local

    written: list[str] = []
    outcomes = list(run_local([_TaskThatKillsItsWorker()], 1, fn=repr, on_stderr=written.append))
    assert len(outcomes) == 1 and (outcomes[0].float_id, outcomes[0].status) == ("f1", FAILED)
    assert outcomes[0].reason == "a worker process died: RuntimeError: this task cannot be rebuilt in a worker"
    assert len(written) == 1 and "Traceback (most recent call last):" in written[0]


def test_last_exception_line_reads_the_last_traceback():
    from rafostrack.batch.pool import last_exception_line

    text = textwrap.dedent(
        """\
        Process ForkServerProcess-1:
        Traceback (most recent call last):
          File "x.py", line 1, in <module>
            import y
        ImportError: first
        some warning printed later
        Traceback (most recent call last):
        Process ForkServerProcess-2:
          File "y.py", line 3, in f
            x = {
                ^
        pkg.mod.CustomError: second: with a colon
        """
    )
    assert last_exception_line(text) == "pkg.mod.CustomError: second: with a colon"
    assert last_exception_line("Traceback (most recent call last):\n  File 'z'\nKeyboardInterrupt\n") == (
        "KeyboardInterrupt"
    )
    assert last_exception_line("no traceback here\nValueError: not after a traceback header\n") is None


def test_a_worker_checks_it_runs_the_batch_process_rafostrack(tmp_path):
    from rafostrack.batch.pool import PACKAGE_DIR, check_worker

    assert Path(PACKAGE_DIR, "batch", "pool.py").is_file()
    check_worker(PACKAGE_DIR)  # the same: no error
    with pytest.raises(RuntimeError, match=f"this worker imports rafostrack from {PACKAGE_DIR}, the batch process"):
        check_worker(str(tmp_path / "rafostrack"))
