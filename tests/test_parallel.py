"""How many kernel threads one float's run takes (`rafostrack.model.parallel`): the cores
idle when it starts, measured from /proc/stat; `--threads` as asked."""

from __future__ import annotations

import numba
import pytest
from click.testing import CliRunner

from rafostrack.cli import main
from rafostrack.model import parallel
from rafostrack.model.parallel import _cpu_times, idle_cores, track_threads


@pytest.mark.parametrize(
    ("busy", "usable", "threads"),
    [(0.0, 2, 2), (0.4, 2, 2), (0.6, 2, 1), (2.0, 2, 1), (7.9, 2, 1), (1.0, 8, 7), (0.0, 1, 1)],
)
def test_idle_cores_leave_the_busy_ones_to_their_work(busy, usable, threads):
    assert idle_cores(busy, usable) == threads


def test_cpu_times_count_idle_and_iowait_as_not_busy(tmp_path):
    stat = tmp_path / "stat"
    # user nice system idle iowait irq softirq steal guest guest_nice
    stat.write_text("cpu  100 5 20 800 50 3 2 0 40 0\ncpu0 50 2 10 400 25 1 1 0 20 0\n")
    assert _cpu_times(stat) == (130.0, 980.0)


def test_a_busy_machine_gets_one_thread_and_threads_asked_are_kept(monkeypatch):
    monkeypatch.setattr(parallel, "usable_cores", lambda: 2)
    monkeypatch.setattr(parallel, "busy_cores", lambda: 2.0)
    assert track_threads(None) == 1
    monkeypatch.setattr(parallel, "busy_cores", lambda: 0.0)
    assert track_threads(None) == min(2, numba.config.NUMBA_NUM_THREADS)
    assert track_threads(1) == 1
    assert track_threads(10_000) == numba.config.NUMBA_NUM_THREADS


def test_track_runs_the_float_on_the_threads_chosen(monkeypatch, tmp_path):
    """`rafostrack track` wraps the whole run in the threads chosen: the float is tracked
    (here, stopped at its start) with numba's thread count set to them."""
    seen = []

    def stop_at_start(*args, **kwargs):
        seen.append(numba.get_num_threads())
        raise SystemExit(0)

    monkeypatch.setattr("rafostrack.run.one_float.track_float", stop_at_start)
    monkeypatch.setattr(parallel, "busy_cores", lambda: 99.0)
    float_file = tmp_path / "f1.csv"
    float_file.write_text("time,toa_s\n")
    monkeypatch.setattr(parallel, "usable_cores", lambda: 2)
    runner, args = CliRunner(), ["track", str(float_file), "--out", str(tmp_path / "out")]
    runner.invoke(main, args)  # every core busy
    monkeypatch.setattr(parallel, "busy_cores", lambda: 0.0)
    runner.invoke(main, [*args, "--threads", "1"])
    runner.invoke(main, args)  # every core idle
    assert seen == [1, 1, min(2, numba.config.NUMBA_NUM_THREADS)]
    assert numba.get_num_threads() == numba.config.NUMBA_NUM_THREADS  # as before, after the run
