"""The ranked evidence of a window with the `exact` engine, in one compiled call per cloud.

What `RankedArrivals.evaluate` composes from `model.measurement` (ranges, predicted
arrivals, detection probabilities, factors) and `engines.exact` (the association sum), for
the default method, done by `_window_kernel.window_evidence_kernel` particle block by
block, with no (particles, beacons, signals) array but the marginals it returns. A
window's terms that do not depend on the particles are gathered once (`CompiledWindow`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..config import ModelConfig
from ..engines.exact import MAX_SIGNALS, echo_pairs
from ..model import measurement as m
from ..model.geodesy import expands_about_centre, stacked_point_terms
from ..model.parallel import threaded
from . import _window_kernel as K
from ._window_kernel import window_evidence_kernel, window_evidence_kernel_threaded


@dataclass(frozen=True)
class CompiledWindow:
    """A window's terms for `_window_kernel.window_evidence_kernel` (its docstring names
    the rows and entries), whatever the particles, with the beacon-table rows of its beacons.
    Kept for every window of a record (`ArrivalLikelihood._per_window`): as few arrays as
    will do."""

    beacon_index: NDArray[np.intp]  # (s,)
    beacon: NDArray[np.float64]  # (6, s)
    toa: NDArray[np.float64]  # (1, K)
    terms: NDArray[np.float64]  # (9,): the signals' and the model's
    no_echo: NDArray[np.float64]  # (1, K), or (0, 1): none
    ratio: NDArray[np.float64]  # (K,) or (0,)
    pairs: NDArray[np.int64]  # (2, pairs): j < j'
    log_e: NDArray[np.float64]  # (1, pairs)


# A window's absent terms, shared by every window (the kernel reads only their lengths).
_NO_ECHO, _NO_RATIO = np.zeros((0, 1)), np.zeros(0)
_NO_PAIRS, _NO_PAIR_TERMS = np.zeros((2, 0), dtype=np.int64), np.zeros((1, 0))
_NO_TERMS = np.zeros((6, 0))


def compiled_window(
    wb: m.WindowBeacons,
    signals: m.SignalTerms,
    toa_s: NDArray,
    model: ModelConfig,
    *,
    ranked: bool,
    source_log_ratio: NDArray | None,
) -> CompiledWindow | None:
    """The `CompiledWindow` of a window's beacons `wb`, its signals' terms and arrival times,
    or None where the compiled path does not apply (no beacon, no signal, or more signals
    than the exact engine takes: `engines.exact.associate` answers those)."""
    k = len(toa_s)
    if len(wb.index) == 0 or k == 0 or k > MAX_SIGNALS:
        return None
    s = len(wb.index)
    beacon = np.empty((6, s))
    beacon[K.LAT], beacon[K.LON], beacon[K.DELAY_S] = wb.lat, wb.lon, wb.delay_s
    beacon[K.SPEED_M_S] = m.beacon_values(wb.sound_speed_m_s, model.sound_speed_m_s, s)
    beacon[K.P_PEAK] = m.beacon_values(wb.p_detect, model.p_detect, s)
    beacon[K.HALF_RANGE_KM] = m.beacon_values(wb.detection_range_km, model.detection_range_km, s)
    pairs, log_e = _NO_PAIRS, _NO_PAIR_TERMS
    if signals.log_echo is not None:
        pair_j, pair_jj, log_e = echo_pairs(signals.log_echo, k)
        pairs = np.stack([pair_j, pair_jj])
        if source_log_ratio is not None:  # as `association_factors` adds it to log E_jj'
            log_e = log_e + source_log_ratio[pair_jj][None, :]
    return CompiledWindow(
        wb.index,
        beacon,
        _kernel_array(np.atleast_2d(toa_s)),
        _terms(signals, model, ranked),
        _NO_ECHO if len(signals.no_echo) == 0 else _kernel_array(signals.no_echo),
        _NO_RATIO if source_log_ratio is None else _kernel_array(source_log_ratio),
        pairs,
        log_e,
    )


def _terms(signals: m.SignalTerms, model: ModelConfig, ranked: bool) -> NDArray[np.float64]:
    """The kernel's `terms`: the window's signals' and the measurement model's."""
    terms = np.empty(9)
    terms[K.LOG_INTENSITY] = signals.log_intensity
    terms[K.HORIZON_S] = signals.horizon
    terms[K.LOG_BASE] = signals.log_base
    terms[K.RANKED] = float(ranked)
    terms[K.SIGMA_S] = model.toa_sigma_s
    terms[K.MULTIPATH_FRACTION] = model.multipath_fraction
    terms[K.MULTIPATH_DELAY_S] = model.multipath_delay_s
    terms[K.MULTIPATH_SHAPE] = model.multipath_delay_shape
    terms[K.FALLOFF_KM] = model.detection_falloff_km
    return terms


def window_evidence(
    window: CompiledWindow,
    lat: NDArray,
    lon: NDArray,
    clock_s: NDArray | None,
    *,
    marginals: bool,
) -> tuple[NDArray[np.float64], NDArray[np.float64] | None]:
    """log p(T | X) (P,) of particles at (lat, lon) with float clocks `clock_s` (or None),
    and with `marginals` P(signal j from beacon i | X)
    (P, s, K), else None."""
    n = len(lat)
    s, k = window.beacon.shape[1], window.toa.shape[1]
    lat, lon = _kernel_array(lat), _kernel_array(lon)
    expanded = expands_about_centre(lat, lon)
    near = far = _NO_TERMS
    if not expanded:
        near, far = stacked_point_terms(lat, lon), stacked_point_terms(window.beacon[K.LAT], window.beacon[K.LON])
    loglik = np.empty(n)
    p_match = np.empty((n if marginals else 0, s, k))
    kernel = window_evidence_kernel_threaded if threaded(n) else window_evidence_kernel
    kernel(
        lat,
        lon,
        np.zeros(0) if clock_s is None else _kernel_array(clock_s),
        expanded,
        near,
        far,
        window.beacon,
        window.toa,
        window.terms,
        window.no_echo,
        window.ratio,
        window.pairs,
        window.log_e,
        marginals,
        loglik,
        p_match,
    )
    return loglik, p_match if marginals else None


def _kernel_array(values: NDArray) -> NDArray[np.float64]:
    """`values` as a writable, C-ordered float64 array (a copy only where it is not one): the
    kernel is compiled for one array type (numba types a read-only array apart)."""
    return np.require(values, dtype=np.float64, requirements=["C", "W"])
