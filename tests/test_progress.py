"""run/progress.py off a terminal (`LineProgress`): a short run prints nothing; a long one
says where it is, at most once per interval, on the stream it was given. On a terminal, a bar."""

from __future__ import annotations

import io
import re

from rafostrack.run.progress import PHASES, LineProgress, progress_for


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


class _Terminal(io.StringIO):
    """A stream that says it is a terminal, as a console does."""

    def isatty(self) -> bool:
        return True


def _short_run(stream: io.StringIO) -> str:
    """What a user sees on `stream` of a short run reported to `progress_for(stream)`."""
    progress = progress_for(stream, "float759")
    for phase in ("reading inputs", "tracking"):
        progress.phase(phase)
    for done in range(1, 11):
        progress.step(done, 10, "pass 1 of 3")
    progress.phase("writing outputs")
    progress.close()
    return stream.getvalue()


def test_progress_for_draws_a_bar_on_a_terminal_and_nothing_off_one_in_a_short_run() -> None:
    """On a terminal: one bar, redrawn in place (carriage returns), naming the float, the
    phases done of four and the current phase, in order, and cleared at the end. Off a
    terminal (a pipe, a log file) the same short run prints nothing at all."""
    assert _short_run(io.StringIO()) == ""
    shown = _short_run(_Terminal())
    assert shown.startswith("\r") and shown.endswith("\r") and "\n" not in shown
    *drawn, cleared = shown.split("\r")[1:-1]
    assert cleared.strip() == ""  # the bar leaves no line behind
    bars = [re.fullmatch(r"float759: (\d)/4 \[\d\d:\d\d\] (?:, )?(.*?) *", bar) for bar in drawn]
    assert all(bars), drawn
    # Each phase drawn as it starts (a redraw every REFRESH_S may draw it again).
    phases = list(dict.fromkeys((int(bar[1]), bar[2]) for bar in bars if bar[2] in PHASES))
    assert phases == [(0, "reading inputs"), (1, "tracking"), (2, "writing outputs")], drawn


def test_each_pass_counts_the_record_s_windows_not_the_end_fix(sim_mission) -> None:
    """The method tells progress of each window of each pass, to as many as the record
    holds: the end fix's filter step is not a window (a 729-window record counts to 729)."""
    import dataclasses

    from rafostrack.config import load_config, with_overrides
    from rafostrack.problem import FloatProblem
    from rafostrack.run.method import track_record

    sim = sim_mission.floats[0]
    assert sim.info.has_end_fix
    record = dataclasses.replace(sim.record, windows=sim.record.windows[:12])
    info = dataclasses.replace(
        sim.info, end_time=record.windows[-1].time + (record.windows[-1].time - record.windows[-2].time)
    )
    config = with_overrides(load_config(), filter={"particles": 100}, calibrate={"enabled": False})
    told: list[tuple[int, int, str]] = []
    track_record(FloatProblem(sim_mission.beacons, info, config), record, progress=lambda *a: told.append(a))
    assert [done for done, _, _ in told] == list(range(1, 13))
    assert {total for _, total, _ in told} == {12}
