"""run/resources.py: the memory estimate said before a run the machine cannot hold."""

from __future__ import annotations

from pathlib import Path

from rafostrack.run.resources import BASE_BYTES, BYTES_PER_PARTICLE, available_bytes, estimate, memory_warning


def test_available_memory_is_read_from_meminfo(tmp_path: Path) -> None:
    meminfo = tmp_path / "meminfo"
    meminfo.write_text("MemTotal:       16000000 kB\nMemAvailable:    8000000 kB\n")
    assert available_bytes(meminfo) == 8000000 * 1024.0
    assert available_bytes(tmp_path / "absent") is None


def test_ten_million_particles_on_an_8_gb_machine_are_warned_with_what_fits() -> None:
    """The case a user met: 10,000,000 particles on 60 windows (5.5 GB and still running
    after 9 minutes); the default 1,000 are not warned."""
    available = 6e9
    message = memory_warning(10_000_000, 60, available)
    assert message is not None
    assert message.startswith("10000000 particles on 60 windows need about 5.3 GB and 15 min of one core")
    fits = int((0.8 * available - BASE_BYTES) / BYTES_PER_PARTICLE)
    assert f"about {fits} fit" in message and estimate(fits, 60)[0] <= 0.8 * available
    assert memory_warning(1000, 60, available) is None
    assert memory_warning(10_000_000, 60, None) is None  # the machine does not say: no guess
