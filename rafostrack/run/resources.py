"""What a run will cost, said before it starts: memory against what the machine has.

Measured on the sample's float759 (298 windows; `rafostrack track --particles P --no-plots`,
peak RSS by /usr/bin/time): 341 MB at 2,000 particles, 347 MB at 20,000, 388 MB at 100,000,
and 7 s, 17 s, 51 s. The passes that feed calibration are capped at `[calibrate]
max_particles`; the last pass's memory grows with its particles (the association's
per-particle tables of a window, not the stored clouds, which the smoother thins), about
`BYTES_PER_PARTICLE` each, and its time with particles x windows.
"""

from __future__ import annotations

from pathlib import Path

from ..errors import Notice, WarningKind

BASE_BYTES = 350e6  # the interpreter, numpy, the record and the capped calibration passes
BYTES_PER_PARTICLE = 500.0
SECONDS_PER_PARTICLE_WINDOW = 1.5e-6  # one core, the default method
MEMORY_SHARE = 0.8  # warn when the estimate passes this share of the available memory


def available_bytes(meminfo: Path = Path("/proc/meminfo")) -> float | None:
    """The memory the kernel says is available (MemAvailable), or None where it is not told."""
    try:
        for line in meminfo.read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return float(line.split()[1]) * 1024.0
    except OSError:
        return None
    return None


def estimate(particles: int, windows: int) -> tuple[float, float]:
    """(bytes, seconds) the default method is expected to take (module docstring)."""
    return BASE_BYTES + BYTES_PER_PARTICLE * particles, SECONDS_PER_PARTICLE_WINDOW * particles * windows


def memory_warning(particles: int, windows: int, available: float | None) -> Notice | None:
    """A one-line warning (a `MEMORY` notice) when the run's estimated memory passes
    `MEMORY_SHARE` of `available`."""
    needed, seconds = estimate(particles, windows)
    if available is None or needed <= MEMORY_SHARE * available:
        return None
    return Notice(
        WarningKind.MEMORY,
        f"{particles} particles on {windows} windows need about {needed / 1e9:.1f} GB and {seconds / 60:.0f} min "
        f"of one core; this machine has {available / 1e9:.1f} GB available: expect swapping or a memory error "
        f"(fewer particles: about {int((MEMORY_SHARE * available - BASE_BYTES) / BYTES_PER_PARTICLE)} fit)",
    )
