"""A computation run beside this process (`rafostrack.run.forked`): the same value as
computed here, an error never lost in the child, the two-filter smoother's work beside (the
backward filter, half the windows' join and summaries) giving the same track bit for bit,
and the source scan's candidates tried half beside."""

from __future__ import annotations

import os
import signal
import sys
import threading
from functools import partial

import numba
import numpy as np
import pandas as pd
import pytest

from rafostrack.config import load_config, with_overrides
from rafostrack.problem import FloatProblem
from rafostrack.run import forked
from rafostrack.run.forked import Forked
from rafostrack.run.one_pass import Tracker

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="rafostrack forks on Linux only")


@pytest.fixture
def spare_core(monkeypatch) -> list[int]:
    """A core to spare, whatever this machine has (one kernel thread each); the list grows
    by one for each child forked."""
    forks: list[int] = []

    def one_thread_each() -> tuple[int, int]:
        forks.append(1)
        return 1, 1

    monkeypatch.setattr(forked, "threads_beside", one_thread_each)
    return forks


def _draws_and_pid() -> tuple[np.ndarray, int]:
    return np.random.default_rng(5).normal(size=1000), os.getpid()


def test_a_forked_computation_gives_what_computing_here_gives(spare_core):
    with Forked(_draws_and_pid) as beside:
        during = numba.get_num_threads()
        draws, pid = beside.result()
    assert spare_core == [1] and during == 1
    assert pid != os.getpid()  # computed in the child
    np.testing.assert_array_equal(draws, _draws_and_pid()[0])


def test_without_a_core_to_spare_it_is_computed_here(monkeypatch):
    monkeypatch.setattr(forked, "threads_beside", lambda: None)
    with Forked(_draws_and_pid) as beside:
        assert beside.result()[1] == os.getpid()
    with Forked(_draws_and_pid, fork=False) as beside:  # not worth a process
        assert beside.result()[1] == os.getpid()


def test_only_the_main_thread_forks(monkeypatch):
    """A program tracking from threads of its own computes there: a thread forking while
    another holds a lock the child needs would leave the child waiting for ever."""
    monkeypatch.setattr(numba, "get_num_threads", lambda: 2)  # two cores, whatever this machine has
    seen: list[tuple[int, int] | None] = []
    worker = threading.Thread(target=lambda: seen.append(forked.threads_beside()))
    worker.start()
    worker.join()
    assert seen == [None] and forked.threads_beside() == (1, 1)


def test_the_kernel_threads_come_back_however_the_block_ends(spare_core):
    before = numba.get_num_threads()
    with pytest.raises(KeyboardInterrupt), Forked(_draws_and_pid):
        raise KeyboardInterrupt  # Ctrl-C during the forward filter: the child is ended
    assert numba.get_num_threads() == before and spare_core == [1]


def test_a_child_that_fails_leaves_the_computation_here(spare_core):
    """Killed, raising, or with a value it cannot send: the computation runs again here,
    where its value is the same and its error has a traceback."""
    parent = os.getpid()

    def killed_in_the_child() -> int:
        if os.getpid() != parent:
            os.kill(os.getpid(), signal.SIGKILL)
        return 42

    def raising_in_the_child() -> int:
        if os.getpid() != parent:
            raise MemoryError
        return 43

    def unpicklable_in_the_child() -> object:
        return (lambda: 44) if os.getpid() != parent else 44

    for compute, value in ((killed_in_the_child, 42), (raising_in_the_child, 43), (unpicklable_in_the_child, 44)):
        with Forked(compute) as beside:
            assert beside.result() == value
    with pytest.raises(ZeroDivisionError), Forked(lambda: 1 / 0) as beside:
        beside.result()
    assert len(spare_core) == 4


def test_the_backward_filter_beside_the_forward_one_gives_the_same_bits(sim_mission, spare_core, monkeypatch):
    """The two-filter smoother with its backward filter and half of its windows' join in
    children, and all of it here: the same track, labels and modes, bit for bit."""
    sim = sim_mission.floats[0]
    config = with_overrides(load_config(), filter={"particles": 300}, smoother={"two_filter": True})
    tracker = Tracker.from_problem(FloatProblem(sim_mission.beacons, sim.info, config))
    beside = tracker.track(sim.record)
    assert spare_core == [1, 1] and beside.smoother == "two_filter"  # the backward filter; half the join
    monkeypatch.setattr(forked, "threads_beside", lambda: None)
    after = tracker.track(sim.record)
    pd.testing.assert_frame_equal(beside.track, after.track, check_exact=True)
    pd.testing.assert_frame_equal(beside.labels, after.labels, check_exact=True)
    pd.testing.assert_frame_equal(beside.estimate.modes, after.estimate.modes, check_exact=True)


def test_the_source_scan_tries_its_candidates_in_order_half_of_them_beside(spare_core):
    """Each candidate's pass (here a stand-in that says where it ran), the later half in the
    child: the results in the candidates' order."""
    from rafostrack.run.schedule_scan import each_beside

    def tracked(candidate):
        return candidate, os.getpid()

    trials = each_beside([partial(tracked, c) for c in ("a", "b", "c")])
    assert [candidate for candidate, _ in trials] == ["a", "b", "c"]
    assert [pid == os.getpid() for _, pid in trials] == [True, True, False]
    assert spare_core == [1]
