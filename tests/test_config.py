from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
from support import error_of, fuzz_settings, needs_hypothesis, only_input_error, write

from rafostrack.config import SECTIONS, default_layer, key_comment, load_config, with_overrides
from rafostrack.errors import InputError

try:
    from hypothesis import given
    from hypothesis import strategies as st
except ImportError:  # pragma: no cover - hypothesis is a test dependency
    st = None

REPO = Path(__file__).resolve().parents[1]


def test_default_toml_sets_every_field_once_and_documents_it():
    """default.toml is the one place defaults live: exactly the fields of the config
    dataclasses, each with a comment (the CLI's help texts come from them)."""
    layer = default_layer()
    assert set(layer) == set(SECTIONS)
    for section, cls in SECTIONS.items():
        assert set(layer[section]) == {f.name for f in dataclasses.fields(cls)}, section
        for key in layer[section]:
            assert key_comment(section, key), (section, key)
    cfg = load_config()
    assert (cfg.filter.likelihood, cfg.filter.engine) == ("ranked", "exact")
    assert 0 < cfg.model.p_detect < 1


def test_no_second_copy_of_the_defaults():
    assert not list((REPO / "configs").glob("default*.toml"))


@pytest.mark.parametrize(
    ("method", "likelihood", "engine"),
    [
        ("exact", "ranked", "exact"),
        ("bp", "ranked", "bp"),
        ("unranked", "unranked", "exact"),
        ("labeled", "labeled", "exact"),
    ],
)
def test_old_method_key_says_what_to_write_instead(tmp_path, method, likelihood, engine):
    path = tmp_path / "old.toml"
    path.write_text(f"[filter]\nmethod = '{method}'\n")
    message = error_of(load_config, [path])
    assert (
        f"[filter] method was split into two keys: write likelihood = '{likelihood}' and engine = '{engine}'" in message
    )


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
        ("[filter]\nengine = 'magic'\n", "[filter] engine: must be one of exact, bp, abc, got 'magic'"),
        (
            "[filter]\nlikelihood = 'rankd'\n",
            "[filter] likelihood: must be one of ranked, unranked, labeled, got 'rankd' (did you mean 'ranked'?)",
        ),
        ("[motion]\nmodel = 'brownian'\n", "[motion] model: must be one of random_walk, ou"),
        (
            "[filter]\nresampling = 'magic'\n",
            "[filter] resampling: must be one of systematic, stratified, residual, multinomial",
        ),
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
    cfg = with_overrides(load_config(), filter={"engine": "bp"})
    assert cfg.filter.engine == "bp"
    with pytest.raises(InputError):
        with_overrides(cfg, model={"clutter_rate": -1.0})


@pytest.mark.reliability
def test_unknown_config_key_suggests_nearest(tmp_path):
    cases = [
        ("[model]\nclutter_rte = 1.0\n", "unknown key [model] clutter_rte (did you mean 'clutter_rate'?)"),
        ("[model]\nzzz = 1.0\n", "unknown key [model] zzz (expected one of sound_speed_m_s, toa_sigma_s,"),
        ("[modle]\np_detect = 0.5\n", "unknown section [modle] (did you mean 'model'?)"),
        ("p_detect = 0.5\n", "key 'p_detect' is outside any [section]; expected it under [model]"),
    ]
    for text, needle in cases:
        path = write(tmp_path / "bad.toml", text)
        message = error_of(load_config, [path])
        assert needle in message and str(path) in message


@pytest.mark.reliability
@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("[model]\ntoa_sigma_s = 'two'\n", "[model] toa_sigma_s: expected a number, got 'two'"),
        (
            '[model]\np_detect = "0.9"\n',
            '[model] p_detect: expected a number, got the string "0.9" (remove the quotes)',
        ),
        ("[filter]\nparticles = '200'\n", '[filter] particles: expected a whole number, got the string "200" (remove'),
        ('[calibrate]\nenabled = "false"\n', '[calibrate] enabled: expected true or false, got the string "false"'),
        ("[filter]\nparticles = 10.5\n", "[filter] particles: expected a whole number, got 10.5"),
        ("[filter]\nparticles = 1e12\n", "[filter] particles: must be between 2 and 10000000"),
        ("[model]\np_detect = nan\n", "[model] p_detect: expected a finite number, got nan"),
        ("[model]\nwindow_s = [1, 2]\n", "[model] window_s: expected a number, got [1, 2]"),
        ("[model]\nwindow_s = 1979-05-27\n", "[model] window_s: expected a number, got datetime.date(1979, 5, 27)"),
        ("[bp] = 1\n", "not valid TOML"),
    ],
)
def test_wrong_types_in_config(tmp_path, text, needle):
    path = write(tmp_path / "c.toml", text)
    message = error_of(load_config, [path])
    assert f"{path}: {needle}" in message


@pytest.mark.reliability
@needs_hypothesis
def test_fuzz_config_toml(tmp_path):
    default = (Path(__file__).resolve().parents[1] / "rafostrack" / "default.toml").read_bytes()
    names = [line.split(" = ")[0] for line in default.decode().splitlines() if " = " in line and line[0].isalpha()]
    sections = [line[1:-1] for line in default.decode().splitlines() if line.startswith("[")]
    value = st.one_of(
        st.integers(-(2**70), 2**70).map(str),
        st.floats().map(repr),
        st.sampled_from(
            [
                *("true", "'exact'", "'bp'", "'x'", "[1, 2]", "{a = 1}", "1979-05-27T07:32:00Z", "07:32:00"),
                *("1979-05-27", "0.5", "1e3", "-0.0", "+inf", "nan", '"""a\nb"""', "0x10", "1_000", "-1", "0"),
            ]
        ),
    )
    line = st.one_of(
        st.sampled_from([*sections, "modle", "x.y", "model.sub", ""]).map(lambda s: f"[{s}]"),
        st.tuples(st.sampled_from([*names, "clutter_rte", "a.b", '"q"']), value).map(lambda kv: f"{kv[0]} = {kv[1]}"),
    )
    document = st.lists(line, max_size=8).map(lambda lines: ("\n".join(lines) + "\n").encode())

    @st.composite
    def mutated(draw):
        data = bytearray(draw(st.one_of(document, st.just(default))))
        for _ in range(draw(st.integers(1, 5))):
            i = draw(st.integers(0, len(data)))
            op = draw(st.integers(0, 2))
            if op == 0:
                data[i:i] = draw(st.sampled_from([b"[", b"]", b"=", b'"', b"\n", b".", b"{", b"}", b"#", b"\xff"]))
            elif op == 1:
                del data[i : i + draw(st.integers(1, 10))]
            else:
                data[i:i] = draw(st.binary(min_size=1, max_size=3))
        return bytes(data)

    path = tmp_path / "c.toml"

    @fuzz_settings()
    @given(st.one_of(document, mutated(), st.binary(max_size=100)))
    def run(data: bytes) -> None:
        path.write_bytes(data)
        only_input_error(load_config, [path])

    run()
