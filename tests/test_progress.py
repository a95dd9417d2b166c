"""run/progress.py off a terminal (`LineProgress`): a short run prints nothing; a long one
says where it is, at most once per interval, on the stream it was given."""

from __future__ import annotations

import io

from rafostrack.run.progress import LineProgress, NoProgress, progress_for


class _Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_a_short_run_off_a_terminal_prints_nothing() -> None:
    stream, clock = io.StringIO(), _Clock()
    progress = LineProgress(stream, "float759", every_s=60, clock=clock)
    for phase in ("reading inputs", "tracking"):
        progress.phase(phase)
    for done in range(1, 300):
        clock.now += 0.1
        progress.step(done, 298, "pass 1 of 3")
    progress.close()
    assert stream.getvalue() == ""


def test_a_long_run_off_a_terminal_says_where_it_is_once_a_minute() -> None:
    stream, clock = io.StringIO(), _Clock()
    progress = LineProgress(stream, "float759", every_s=60, clock=clock)
    progress.phase("tracking")
    for done in range(1, 301):
        clock.now += 1.0  # a window a second: 300 s in all
        progress.step(done, 300, "pass 2 of 3")
    lines = stream.getvalue().splitlines()
    assert lines[0] == "rafostrack: float759: tracking, pass 2 of 3, window 60/300, 60 s"
    assert len(lines) == 5 and all(line.startswith("rafostrack: float759: tracking, pass 2 of 3, ") for line in lines)


def test_off_a_terminal_the_progress_is_line_progress() -> None:
    assert isinstance(progress_for(io.StringIO(), "f"), LineProgress)
    assert not isinstance(progress_for(io.StringIO(), "f"), NoProgress)
