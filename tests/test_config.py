from __future__ import annotations

from pathlib import Path

import pytest

from rafostrack.config import load_config, with_overrides
from rafostrack.errors import InputError

REPO = Path(__file__).resolve().parents[1]


def test_defaults_file_is_the_packaged_one():
    assert (REPO / "configs" / "default.toml").read_text() == (REPO / "rafostrack" / "default.toml").read_text()
    cfg = load_config()
    assert cfg.filter.method == "exact"
    assert 0 < cfg.model.p_detect < 1


def test_layers_apply_in_order(tmp_path):
    a = tmp_path / "a.toml"
    a.write_text("[model]\nclutter_rate = 2.0\ntoa_sigma_s = 3\n[filter]\nparticles = 50\n")
    b = tmp_path / "b.toml"
    b.write_text("[model]\nclutter_rate = 0.5\n")
    cfg = load_config([a, b], {"filter": {"particles": 70}})
    assert cfg.model.clutter_rate == 0.5
    assert cfg.model.toa_sigma_s == 3.0 and isinstance(cfg.model.toa_sigma_s, float)
    assert cfg.filter.particles == 70


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("[model]\nclutter_rte = 1.0\n", "unknown key [model] clutter_rte (did you mean 'clutter_rate'?)"),
        ("[modle]\nclutter_rate = 1.0\n", "unknown section [modle] (did you mean 'model'?)"),
        ("[model]\np_detect = 1.0\n", "[model] p_detect: must be strictly between 0 and 1"),
        ("[model]\ntoa_sigma_s = 'two'\n", "[model] toa_sigma_s: expected a number"),
        ("[filter]\nparticles = 10.5\n", "[filter] particles: expected a whole number"),
        ("[filter]\nmethod = 'magic'\n", "[filter] method: must be one of exact, bp, unranked, labeled"),
        ("[model\n", "not valid TOML"),
    ],
)
def test_bad_config_is_one_clear_error(tmp_path, text, needle):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(InputError) as err:
        load_config([path])
    assert needle in str(err.value) and str(path) in str(err.value)


def test_missing_config_file(tmp_path):
    with pytest.raises(InputError, match="config file not found"):
        load_config([tmp_path / "nope.toml"])


def test_with_overrides_validates():
    cfg = with_overrides(load_config(), filter={"method": "bp"})
    assert cfg.filter.method == "bp"
    with pytest.raises(InputError):
        with_overrides(cfg, model={"clutter_rate": -1.0})
