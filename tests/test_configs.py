"""The example configurations in `configs/`: each parses, every key it sets is a known key
and is applied, and the quick-look one tracks the bundled sample float811."""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import rafostrack
from rafostrack.config import load_config
from rafostrack.errors import InputError
from rafostrack.sim.evaluate import position_errors_km

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = sorted((ROOT / "configs").glob("*.toml"))


def test_the_examples_are_there():
    assert {p.name for p in CONFIGS} >= {"dimes-like.toml", "weddell-sparse.toml", "quick-look.toml"}
    readme = (ROOT / "configs" / "README.md").read_text()
    assert all(p.name in readme for p in CONFIGS)


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: p.stem)
def test_every_key_is_known_and_applied(path):
    layer = tomllib.loads(path.read_text())
    config = load_config([path])
    assert layer, f"{path.name} sets nothing"
    for section, values in layer.items():
        for key, value in values.items():
            assert getattr(getattr(config, section), key) == value, f"[{section}] {key}"
            assert (section, key) in config.explicit


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: p.stem)
def test_a_misspelt_key_would_be_refused(path, tmp_path):
    """load_config refuses unknown keys, so the test above holds each key to the schema."""
    text = path.read_text()
    section, key = next((s, k) for s, values in tomllib.loads(text).items() for k in values)
    bad = tmp_path / path.name
    bad.write_text(text.replace(f"\n{key} =", f"\n{key}x =", 1))
    with pytest.raises(InputError, match=rf"unknown key \[{section}\] {key}x"):
        load_config([bad])


def test_quick_look_tracks_the_sample_float811():
    """One pass (no calibration), 200 particles, FFBSm: the whole float in a second or two
    once compiled, and within a few km of the simulated truth (2.7 km RMSE when written)."""
    run = rafostrack.track(ROOT / "data" / "samples" / "float811.csv", config_file=ROOT / "configs" / "quick-look.toml")
    info = run.run_info
    assert info["config"]["filter"]["particles"] == 200
    assert info["calibration"] is None and info["smoother"] == "ffbsm"
    assert info["counts"]["windows"] == len(run.track) > 300
    truth = pd.read_csv(ROOT / "data" / "samples" / "truth" / "float811.csv")
    truth["time"] = pd.to_datetime(truth["time"], utc=True).dt.tz_localize(None)
    track = run.track.assign(time=pd.to_datetime(run.track["time"], utc=True).dt.tz_localize(None))
    error_km = position_errors_km(track, truth)
    assert np.sqrt(np.mean(error_km**2)) < 10.0 and error_km.max() < 40.0
