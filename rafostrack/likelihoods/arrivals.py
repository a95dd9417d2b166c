"""Arrival-time evidence of one listening window (paper section 2).

Three evidence models, registered in `ARRIVAL_LIKELIHOODS` under the config's
`[filter] likelihood`:

- `ranked` (eqs. 14-18): the stored TOAs are the earliest of the window; the association
  of beacons to signals is summed out by the configured engine (`rafostrack.engines`), or,
  for a simulating engine (`abc`), the window's likelihood is estimated from windows it
  simulates from the predicted arrivals and detection probabilities;
- `unranked` (the paper's baseline, eq. 19): the same sum, but an unheard beacon costs
  1 - Pd whatever its predicted arrival;
- `labeled` (eq. 20): the arrival file's `beacon_id` column as known labels.

The factors themselves (predicted arrivals, w_ij, u_i) are `rafostrack.model.measurement`'s.
"""

from __future__ import annotations

import copy
import dataclasses
import zlib
from collections.abc import Callable
from typing import Any, TypeVar

import numpy as np
from numpy.typing import NDArray

from ..config import Config, ModelConfig, QualityConfig
from ..domain import BeaconTable, FloatInfo, Particles, Window
from ..engines import Engine, SimulatingEngine, WindowPrediction, engine_from_config, exact
from ..errors import InputError, Notice, WarningKind
from ..model import measurement as m
from .base import Evidence, Likelihood, outlier_scale
from .quality import quality_log_ratio
from .window_evidence import CompiledWindow, compiled_window, window_evidence

# Particles carrying less than this fraction of the mass are left out when association
# marginals are recomputed for a reweighted (smoothed) cloud.
NEGLIGIBLE_MASS = 1e-6

T = TypeVar("T")


def with_particle_clock(mu: NDArray[np.float64], particles: Particles) -> NDArray[np.float64]:
    """Predicted arrivals (P, s) with each particle's float clock correction added, where
    the clock is part of the state (`motion.clock.ClockWalk`): mu_i(X, t) + c."""
    return mu if particles.clock_s is None else mu + particles.clock_s[:, None]


class ArrivalLikelihood(Likelihood):
    """Evidence of a window's stored arrival times, for one float."""

    def __init__(self, beacons: BeaconTable, info: FloatInfo, model: ModelConfig):
        self.beacons = beacons
        self.info = info
        self.model = model
        self._windows: dict[int, tuple[Window, Any]] = {}

    def with_toa_sigma(self, toa_sigma_s: float) -> ArrivalLikelihood:
        """A copy with the TOA noise sd set to `toa_sigma_s` (e.g. widened for a coarse grid)."""
        other = copy.copy(self)
        other.model = dataclasses.replace(self.model, toa_sigma_s=toa_sigma_s)
        other._windows = {}
        return other

    def _per_window(self, window: Window, make: Callable[[Window], T]) -> T:
        """`make(window)`: what every evaluation of `window` shares, whatever the particles
        (its beacons and their delays, its signals' terms), made once and kept for as long
        as this likelihood, whose table and model it is of. A window is evaluated some ten
        times a pass: the filters, the labels, the recovery search."""
        kept = self._windows.get(id(window))
        if kept is None or kept[0] is not window:
            kept = (window, make(window))
            self._windows[id(window)] = kept
        return kept[1]

    def label_probs(
        self, particles: Particles, weights: NDArray, window: Window
    ) -> tuple[NDArray[np.float64], NDArray[np.intp]]:
        """Association marginals (s, K) of `window` under `weights` on `particles`, and the
        beacon-table rows of their s rows.

        Recomputes the per-particle marginals on the particles that carry all but a
        negligible fraction of the mass (used for smoothed labels).
        """
        order = np.argsort(weights)[::-1]
        cut = np.searchsorted(np.cumsum(weights[order]), 1.0 - NEGLIGIBLE_MASS) + 1
        keep = np.sort(order[:cut])
        evidence = self.evaluate(particles.take(keep), window)
        if evidence.p_match is None:
            raise ValueError(f"{type(self).__name__} gives no association marginals")
        w = weights[keep] / weights[keep].sum()
        return np.einsum("p,psk->sk", w, evidence.p_match), evidence.beacon_index


class RankedArrivals(ArrivalLikelihood):
    """p(T_1..T_K | X): the association sum of the ranked model (or the unranked baseline).

    With a simulating engine the window itself is passed on (`engines.WindowPrediction`),
    with the seed material of its draws: `seed` ([filter] seed), the float id and the
    window's time."""

    def __init__(
        self,
        beacons: BeaconTable,
        info: FloatInfo,
        model: ModelConfig,
        engine: Engine | SimulatingEngine,
        ranked: bool = True,
        seed: int = 0,
        quality: QualityConfig | None = None,
    ):
        super().__init__(beacons, info, model)
        # Which kind of engine, decided once (a check against a runtime Protocol costs ~50 us).
        self._simulator = engine if isinstance(engine, SimulatingEngine) else None
        self._sum = engine if not isinstance(engine, SimulatingEngine) else None
        self.ranked = ranked
        self.seed = seed
        self.quality = quality

    def evaluate(self, particles: Particles, observation: Window, *, marginals: bool = True) -> Evidence:
        window = observation
        terms = self._per_window(window, self._window_terms)
        if isinstance(terms, CompiledWindow):
            lat, lon, clock_s = particles.lat, particles.lon, particles.clock_s
            loglik, p_match = window_evidence(terms, lat, lon, clock_s, marginals=marginals)
            return Evidence(loglik, terms.beacon_index, p_match)
        wb, signals = terms
        mu, p_detect = m.beacon_prediction(wb, self.model, particles.lat, particles.lon)
        mu = with_particle_clock(mu, particles)
        if self._simulator is not None:
            time_ns = int(np.asarray(window.time, dtype="datetime64[ns]").astype(np.int64)) % (1 << 64)
            entropy = (self.seed, zlib.crc32(self.info.float_id.encode("utf-8")), time_ns)
            prediction = WindowPrediction(
                window.toa_s, mu, p_detect, self.info.max_signals, self.info.window_s, self.model, entropy, self.ranked
            )
            assoc = self._simulator.simulate(prediction, marginals=marginals)
            return Evidence(assoc.log_z, wb.index, assoc.p_match)
        factors = m.association_factors(
            mu,
            p_detect,
            window.toa_s,
            max_signals=self.info.max_signals,
            window_s=self.info.window_s,
            model=self.model,
            ranked=self.ranked,
            source_log_ratio=self._source_log_ratio(window),
            signals=signals,
        )
        assert self._sum is not None
        assoc = self._sum(factors.log_match, factors.log_unheard, marginals=marginals, log_echo=factors.log_echo)
        return Evidence(factors.log_base + assoc.log_z, wb.index, assoc.p_match if marginals else None)

    def _window_terms(self, window: Window) -> CompiledWindow | tuple[m.WindowBeacons, m.SignalTerms | None]:
        """With the exact engine, the window's terms for the compiled evidence
        (`window_evidence`); else its active beacons and, for the association sum, its
        signals' terms."""
        wb = m.window_beacons(self.beacons, self.info, window.time)
        if self._simulator is not None:
            return wb, None
        signals = m.signal_terms(
            window.toa_s, max_signals=self.info.max_signals, window_s=self.info.window_s, model=self.model
        )
        if self._sum is exact.associate:
            ratio = self._source_log_ratio(window)
            toa = window.toa_s
            compiled = compiled_window(wb, signals, toa, self.model, ranked=self.ranked, source_log_ratio=ratio)
            if compiled is not None:
                return compiled
        return wb, signals

    def _source_log_ratio(self, window: Window) -> NDArray | None:
        """The window's correlation heights as source-vs-clutter evidence, when configured."""
        if self.quality is None or not self.quality.enabled or window.quality is None:
            return None
        return quality_log_ratio(window.quality, self.quality)


class LabelledArrivals(ArrivalLikelihood):
    """Eq. (20) on the window's labelled beacons: prod over labelled TOAs of f(T_j - mu_{R_j}).

    The active period is not enforced (the label says the beacon was heard); a labelled TOA
    that no particle explains has its sd widened, with a warning.
    """

    def __init__(self, beacons: BeaconTable, info: FloatInfo, model: ModelConfig):
        super().__init__(beacons, info, model)
        self._beacon_row = beacons.index_of()

    def evaluate(self, particles: Particles, observation: Window, *, marginals: bool = True) -> Evidence:
        window = observation
        wb, label_index = self._per_window(window, self._window_labels)
        assert window.beacon_id is not None  # `_window_labels` refuses a window without
        mu = m.predicted_toa_s(m.beacon_ranges_m(particles.lat, particles.lon, wb), wb, self.model)
        mu = with_particle_clock(mu, particles)
        labelled = np.flatnonzero(label_index >= 0)
        p_match = None
        if marginals:
            p_match = np.zeros((len(particles), len(wb.index), window.n_signals))
            p_match[:, label_index[labelled], labelled] = 1.0
        nearest = np.full(window.n_signals, 0.0)
        if len(labelled):
            resid = window.toa_s[labelled][None, :] - mu[:, label_index[labelled]]
            nearest[labelled] = np.abs(resid).min(axis=0) / self.model.toa_sigma_s
        scale = outlier_scale(nearest)
        warnings = tuple(
            Notice(
                WarningKind.OUTLIER_TOAS,
                f"{self.info.float_id}: window {np.datetime_as_string(window.time, 's')}Z: TOA {window.toa_s[j]:g} s "
                f"labelled {window.beacon_id[j]} is {nearest[j]:.0f} sd from every particle's prediction; "
                f"its sd was widened {scale[j]:.1f}x",
            )
            for j in np.flatnonzero(scale > 1.0)
        )
        loglik = m.labeled_loglik(mu, window.toa_s, label_index, self.model, sigma_scale=scale)
        return Evidence(loglik, wb.index, p_match, warnings)

    def _window_labels(self, window: Window) -> tuple[m.WindowBeacons, NDArray[np.intp]]:
        """The window's labelled beacons (ascending table rows) and, per signal, its
        beacon's column among them (-1: clutter)."""
        if window.beacon_id is None:
            raise InputError(
                f"likelihood 'labeled' needs a beacon_id column in the arrival file of {self.info.float_id}"
            )
        rows = np.array(sorted({self._beacon_row[b] for b in window.beacon_id if b is not None}), dtype=np.intp)
        column = {int(r): c for c, r in enumerate(rows)}
        label_index = [column[self._beacon_row[b]] if b is not None else -1 for b in window.beacon_id]
        return m.window_beacons(self.beacons, self.info, window.time, index=rows), np.array(label_index, dtype=np.intp)


ArrivalFactory = Callable[[BeaconTable, FloatInfo, Config], ArrivalLikelihood]

ARRIVAL_LIKELIHOODS: dict[str, ArrivalFactory] = {
    "ranked": lambda b, i, c: RankedArrivals(b, i, c.model, engine_from_config(c), True, c.filter.seed, c.quality),
    "unranked": lambda b, i, c: RankedArrivals(b, i, c.model, engine_from_config(c), False, c.filter.seed, c.quality),
    "labeled": lambda b, i, c: LabelledArrivals(b, i, c.model),
}
