"""The compiled window evidence (`likelihoods.window_evidence`) against its composition.

The oracle is the numpy composition of the measurement model's stages and the exact
engine (each tested on its own: tests/test_model.py, tests/test_engines.py against brute
enumeration): the same bits, for every option the kernel takes, on small clouds (exact
ranges) and large ones (ranges about the cloud's centre), serial and threaded.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from rafostrack.config import load_config
from rafostrack.engines import exact
from rafostrack.likelihoods import _window_kernel
from rafostrack.likelihoods.window_evidence import compiled_window, window_evidence
from rafostrack.model import measurement as m
from rafostrack.model.parallel import kernel_threads


def composed(wb, model, toa, lat, lon, clock_s, *, ranked, ratio, marginals):
    """log p(T | X) and the marginals by the numpy stages and `engines.exact.associate`."""
    mu, p_detect = m.beacon_prediction(wb, model, lat, lon)
    if clock_s is not None:
        mu = mu + clock_s[:, None]
    factors = m.association_factors(
        mu, p_detect, toa, max_signals=4, window_s=model.window_s, model=model, ranked=ranked, source_log_ratio=ratio
    )
    assoc = exact.associate(factors.log_match, factors.log_unheard, marginals=marginals, log_echo=factors.log_echo)
    return factors.log_base + assoc.log_z, assoc.p_match


def case(seed: int, n: int, *, echo: float, multipath: float, shape: int, per_beacon: bool, half_range_km: float):
    """A window of 4 stored TOAs from 6 beacons about a cloud of n particles, 300-1200 km off."""
    rng = np.random.default_rng(seed)
    base = load_config().model
    model = dataclasses.replace(
        base,
        toa_sigma_s=1.5,
        echo_fraction=echo,
        multipath_fraction=multipath,
        multipath_delay_shape=shape,
        detection_range_km=half_range_km,
        window_s=1800.0,
        max_signals=4,
    )
    s = 6
    b_lat, b_lon = -55.0 + rng.uniform(-8, 8, s), -40.0 + rng.uniform(-12, 12, s)
    extra = {}
    if per_beacon:  # some beacons calibrated, others (NaN) the model's
        extra = {
            "sound_speed_m_s": np.where(rng.random(s) < 0.5, np.nan, 1480.0 + rng.normal(0, 3, s)),
            "p_detect": np.where(rng.random(s) < 0.5, np.nan, rng.uniform(0.5, 0.95, s)),
            "detection_range_km": np.where(rng.random(s) < 0.5, np.nan, rng.uniform(0, 900, s)),
        }
    wb = m.WindowBeacons(np.arange(s), b_lat, b_lon, rng.uniform(0, 300, s), **extra)
    lat, lon = -55.0 + rng.normal(0, 0.3, n), -40.0 + rng.normal(0, 0.5, n)
    mu, _ = m.beacon_prediction(wb, model, np.array([-55.0]), np.array([-40.0]))
    toa = np.sort(np.concatenate([mu[0, :3] + rng.normal(0, 2, 3), rng.uniform(0, 1800, 1)]))
    return model, wb, np.clip(toa, 1.0, 1799.0), lat, lon


CASES = [
    dict(echo=0.0, multipath=0.0, shape=1, per_beacon=False, half_range_km=0.0),
    dict(echo=0.0, multipath=0.0, shape=1, per_beacon=False, half_range_km=700.0),
    dict(echo=0.0, multipath=0.2, shape=1, per_beacon=True, half_range_km=700.0),
    dict(echo=0.3, multipath=0.2, shape=2, per_beacon=True, half_range_km=0.0),
]


@pytest.mark.parametrize("n", [7, 300])  # exact ranges below geodesy.MIN_EXPANDED, the expansion above
@pytest.mark.parametrize("options", CASES)
@pytest.mark.parametrize("ranked", [True, False])
def test_compiled_evidence_is_the_composition_bit_for_bit(n: int, options: dict, ranked: bool) -> None:
    for seed in range(3):
        model, wb, toa, lat, lon = case(seed, n, **options)
        rng = np.random.default_rng(seed + 10)
        clock_s = rng.normal(0, 2, n) if seed == 1 else None
        ratio = rng.normal(0, 1, len(toa)) if seed == 2 else None
        signals = m.signal_terms(toa, max_signals=4, window_s=model.window_s, model=model)
        window = compiled_window(wb, signals, toa, model, ranked=ranked, source_log_ratio=ratio)
        assert window is not None
        for marginals in (True, False):
            got, got_match = window_evidence(window, lat, lon, clock_s, marginals=marginals)
            want, want_match = composed(wb, model, toa, lat, lon, clock_s, ranked=ranked, ratio=ratio, marginals=True)
            assert np.array_equal(got, want)
            assert np.all(np.isfinite(got))
            if marginals:
                assert np.array_equal(got_match, want_match)
            else:
                assert got_match is None


def test_threads_give_the_same_bits() -> None:
    model, wb, toa, lat, lon = case(5, 700, **CASES[2])
    signals = m.signal_terms(toa, max_signals=4, window_s=model.window_s, model=model)
    window = compiled_window(wb, signals, toa, model, ranked=True, source_log_ratio=None)
    with kernel_threads(1):
        serial = window_evidence(window, lat, lon, None, marginals=True)
    with kernel_threads(2):
        threaded = window_evidence(window, lat, lon, None, marginals=True)
    assert np.array_equal(serial[0], threaded[0])
    assert np.array_equal(serial[1], threaded[1])


def test_windows_the_exact_engine_answers_alone_are_not_compiled() -> None:
    model, wb, toa, _, _ = case(0, 10, **CASES[0])
    signals = m.signal_terms(toa, max_signals=4, window_s=model.window_s, model=model)
    assert compiled_window(wb, signals, toa, model, ranked=True, source_log_ratio=None) is not None
    empty = m.signal_terms(toa[:0], max_signals=4, window_s=model.window_s, model=model)
    assert compiled_window(wb, empty, toa[:0], model, ranked=True, source_log_ratio=None) is None
    many = np.linspace(1.0, 1700.0, exact.MAX_SIGNALS + 1)
    signals = m.signal_terms(many, max_signals=20, window_s=model.window_s, model=model)
    assert compiled_window(wb, signals, many, model, ranked=True, source_log_ratio=None) is None


def test_the_kernels_cache_key_names_the_modules_it_compiles_in() -> None:
    """numba refreshes a cached kernel when its own file changes, not a callee's elsewhere:
    the digest written in `_window_kernel` must be that of the modules it compiles in."""
    assert _window_kernel.dependencies_sha256() == _window_kernel.DEPENDENCIES_SHA256, (
        "a module compiled into likelihoods/_window_kernel.py changed: set its DEPENDENCIES_SHA256 to "
        f"{_window_kernel.dependencies_sha256()} (so that numba's cache of the kernel is refreshed)"
    )
