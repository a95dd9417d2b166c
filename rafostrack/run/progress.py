"""Progress of one `rafostrack track` run on a terminal: which phase it is in, how long so far.

`track_float` reports its phases (reading, tracking, writing, plots) to a `Progress`;
`progress_for(stream)` gives a tqdm bar when `stream` is a terminal, and otherwise (a
pipe, a log file, cron) a line only when a run is long (`LineProgress`), so scripted
output of ordinary runs stays one line per float and a long one is never silent.

The bar's elapsed time ticks while a phase runs (a refresh every `REFRESH_S`), so a long
tracking phase is never silent. Within the tracking phase, `step(done, total, what)` shows
the windows done by each filter pass as `rafostrack.run.method.track_record` reports them.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import IO, Protocol

# The phases of one float, in order: the bar advances by one at the start of each.
PHASES = ("reading inputs", "tracking", "writing outputs", "drawing plots")
REFRESH_S = 0.5
LINE_EVERY_S = 60.0  # off a terminal, a line at most this often (`LineProgress`)


class Progress(Protocol):
    def phase(self, name: str) -> None: ...

    def step(self, done: int, total: int, what: str = "") -> None: ...

    def close(self) -> None: ...


class NoProgress:
    """Reports nothing (not a terminal, or progress not wanted)."""

    def phase(self, name: str) -> None:
        pass

    def step(self, done: int, total: int, what: str = "") -> None:
        pass

    def close(self) -> None:
        pass


class TerminalProgress:
    """A tqdm bar over `PHASES` on `stream`, labelled with the float and the current phase,
    its elapsed time refreshed every `REFRESH_S` by a daemon thread."""

    def __init__(self, stream: IO[str], label: str = "", refresh_s: float = REFRESH_S):
        from tqdm import tqdm

        self._bar = tqdm(
            total=len(PHASES),
            file=stream,
            desc=label,
            bar_format="{desc}: {n_fmt}/{total_fmt} [{elapsed}] {postfix}",
            leave=False,
            dynamic_ncols=True,
        )
        self._stream = stream
        self._phases: list[str] = []
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._tick, args=(refresh_s,), daemon=True)
        self._thread.start()

    def _tick(self, every_s: float) -> None:
        while not self._stop.wait(every_s):
            with self._lock:
                self._bar.refresh()

    def phase(self, name: str) -> None:
        with self._lock:
            if self._phases:
                self._bar.update(1)
            self._phases.append(name)
            self._bar.set_postfix_str(name, refresh=True)

    def step(self, done: int, total: int, what: str = "") -> None:
        """Within the current phase: `done` of `total` steps of `what` (e.g. a filter pass)."""
        with self._lock:
            current = self._phases[-1] if self._phases else ""
            detail = f"{what}, " if what else ""
            self._bar.set_postfix_str(f"{current} ({detail}window {done}/{total})", refresh=False)

    def close(self) -> None:
        self._stop.set()
        self._thread.join()
        with self._lock:
            self._bar.close()
            self._stream.flush()  # the bar's last clearing before whatever is printed next


def is_terminal(stream: IO[str]) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):  # closed or not a file
        return False


class LineProgress:
    """Off a terminal (a pipe, a log file, cron): a line on `stream` when a phase has run for
    `every_s` and every `every_s` after, saying where the run is ("tracking, pass 2 of 3,
    window 300/729, 120 s"); a run shorter than `every_s` prints nothing."""

    def __init__(
        self,
        stream: IO[str],
        label: str = "",
        every_s: float = LINE_EVERY_S,
        clock: Callable[[], float] = time.monotonic,
    ):
        self._stream, self._label, self._every_s, self._clock = stream, label, every_s, clock
        self._started = clock()
        self._next = self._started + every_s
        self._phase = ""

    def _maybe_say(self, detail: str) -> None:
        now = self._clock()
        if now < self._next:
            return
        self._next = now + self._every_s
        where = f"{self._label}: " if self._label else ""
        self._stream.write(f"rafostrack: {where}{detail}, {now - self._started:.0f} s\n")
        self._stream.flush()

    def phase(self, name: str) -> None:
        self._phase = name
        self._maybe_say(name)

    def step(self, done: int, total: int, what: str = "") -> None:
        detail = f"{what}, " if what else ""
        self._maybe_say(f"{self._phase}, {detail}window {done}/{total}")

    def close(self) -> None:
        pass


def progress_for(stream: IO[str], label: str = "") -> Progress:
    """A bar on `stream` when it is a terminal, else a line now and then (`LineProgress`)."""
    return TerminalProgress(stream, label) if is_terminal(stream) else LineProgress(stream, label)
