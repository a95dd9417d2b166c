"""Fixtures shared by the test modules (plain helpers are in support.py)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from support import simulated_mission_dir

import rafostrack.io.atomic
from rafostrack.config import load_config
from rafostrack.sim.scenarios import synthetic_scenario
from rafostrack.sim.simulate import SimulatedMission, simulate_mission


@pytest.fixture(scope="session")
def sim_mission_dir(tmp_path_factory) -> Path:
    """A small simulated mission directory (one float, `sim1`, 20 days) tracked with 200
    particles (its rafostrack.toml says so). Copy it before changing it."""
    return simulated_mission_dir(tmp_path_factory.mktemp("mission"), seed=3)


@pytest.fixture(scope="session")
def sim_mission() -> SimulatedMission:
    """One synthetic float, 60 days, clutter 1 per window: the tracker's own model, one
    arrival per detected source (no multipath, no echoes)."""
    beacons, floats = synthetic_scenario(days=60, rng=7)
    model = dataclasses.replace(load_config().model, multipath_fraction=0.0, echo_fraction=0.0)
    return simulate_mission(beacons, floats, model, np.random.default_rng(7))


@pytest.fixture(scope="session")
def quality_mission(sim_mission_dir, tmp_path_factory) -> Path:
    """The simulated mission with a correlation height (`quality`) per TOA."""
    from field_files import mission_with_quality

    return mission_with_quality(sim_mission_dir, tmp_path_factory.mktemp("qmission") / "m")


@pytest.fixture
def atomic_writes(monkeypatch) -> list[Path]:
    """The paths `rafostrack.io.atomic.write_text_atomic` writes during the test, in order
    (the writes still happen)."""
    written: list[Path] = []
    original = rafostrack.io.atomic.write_text_atomic

    def recorded(path, text):
        written.append(Path(path))
        original(path, text)

    monkeypatch.setattr(rafostrack.io.atomic, "write_text_atomic", recorded)
    return written
