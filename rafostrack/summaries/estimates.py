"""Per-window estimates from filter steps under a set of weights (filtered or smoothed).

For each window: the position and its covariance ellipse, the spread, the ESS, whether
the posterior has two separate modes, and each TOA's most probable label. Where the
posterior is ambiguous (two modes), `lat`, `lon` and the ellipse describe the heavier
mode (a position the float may really have had, not the point between the modes), `sd_km`
the whole posterior, and both modes go to the modes table.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

from ..config import AmbiguityConfig
from ..domain import Cloud, Particles, Window
from ..filtering.filter import Step
from ..smoothing.ffbsm import Smoothed
from ..smoothing.split import Split, sides
from .posterior import Gaussian2D, Modes, summarise, two_modes

TRACK_COLUMNS = (
    "float_id",
    "time",
    "lat",
    "lon",
    "sd_km",
    "smaj_km",
    "smin_km",
    "angle_deg",
    "ess",
    "n_signals",
    "loglik",
    "ambiguous",
    "second_mode_km",
    "status",
)
LABEL_COLUMNS = ("float_id", "time", "rank", "toa_s", "beacon_id", "prob", "p_clutter")
MODE_COLUMNS = ("float_id", "time", "mode", "lat", "lon", "weight", "sd_km")


@dataclass(frozen=True)
class Estimate:
    """A float's track, labels and modes; `kind` is "filtered" or "smoothed"."""

    kind: str
    track: pd.DataFrame
    labels: pd.DataFrame
    modes: pd.DataFrame


def label_rows(
    float_id: str, window: Window, beacon_ids: NDArray, beacon_index: NDArray, probs: NDArray
) -> list[tuple]:
    """One row per TOA: the most probable of (each beacon, clutter) and its probability."""
    rows = []
    p_clutter = np.clip(1.0 - probs.sum(axis=0), 0.0, 1.0)
    for j, toa in enumerate(window.toa_s):
        best = int(np.argmax(probs[:, j])) if probs.shape[0] else -1
        if best >= 0 and probs[best, j] > p_clutter[j]:
            beacon, prob = beacon_ids[beacon_index[best]], float(probs[best, j])
        else:
            beacon, prob = None, float(p_clutter[j])
        rows.append((float_id, window.time, j + 1, float(toa), beacon, prob, float(p_clutter[j])))
    return rows


@dataclass(frozen=True)
class EstimateRows:
    """Rows of an estimate's tables (`EstimateBuilder.rows`), and the filter's ESS of each window."""

    track: list[tuple]
    labels: list[tuple]
    modes: list[tuple]
    window_ess: list[float]


# Association marginals (s, K) of a window under some weights, and their beacon-table rows.
LabelProbs = Callable[[Particles, NDArray, Window], tuple[NDArray, NDArray]]
# Region labels of particles (regions parted by forbidden ground), or None.
Regions = Callable[[Particles], NDArray[np.int64] | None]


class EstimateBuilder:
    """Accumulates one output row per window (and its labels, and its modes if ambiguous),
    from steps given one at a time, so a filter-only run can summarise its steps as they
    are made and keep none of them."""

    def __init__(
        self,
        float_id: str,
        beacon_ids: NDArray,
        ambiguity: AmbiguityConfig,
        kind: str,
        regions: Regions | None = None,
    ):
        """`regions(particles)`: labels of regions parted by forbidden ground (context
        constraints, `likelihoods.MoveFactor.regions`), or None; a posterior in two of them
        is reported by its heavier part (`posterior.two_modes`)."""
        self.regions = regions
        self.float_id = float_id
        self.beacon_ids = beacon_ids
        self.ambiguity = ambiguity
        self.kind = kind
        self._track: list[tuple] = []
        self.window_ess: list[float] = []  # the filter's ESS of each window added
        self._labels: list[tuple] = []
        self._modes: list[tuple] = []

    def add(
        self,
        step: Step,
        weights: NDArray | None = None,
        label_probs: LabelProbs | None = None,
        extra_cov_km2: NDArray | None = None,
        split: Split | None = None,
    ) -> None:
        """Summarise `step` under `weights` (default: its filter weights). Labels come from
        the step's filtered marginals, or from `label_probs` under the given weights;
        `extra_cov_km2` (2, 2) is added to every position's covariance (a regularised
        smoother's kernel, the calibration's undetermined nuisances). A `split` window (the
        two-filter smoother's filters apart, `smoothing.split`) is ambiguous: its modes are
        the particles nearer each filter's mean, its covariance widened to cover both."""
        window = step.window
        if window is None:  # a position fix: an observation, not an output row
            return
        cloud = step.cloud
        w = cloud.weights if weights is None else weights
        modes = self._modes_of(cloud, w, extra_cov_km2, split)
        self.window_ess.append(step.ess)
        position = modes.position
        smaj, smin, angle = position.ellipse()
        self._track.append(
            (
                self.float_id,
                window.time,
                position.lat,
                position.lon,
                modes.whole.sd_km,
                smaj,
                smin,
                angle,
                step.ess,  # the filter's, smoothed or not (the column's documented meaning)
                window.n_signals,
                step.loglik,
                modes.ambiguous,
                modes.separation_km if modes.ambiguous else np.nan,
            )
        )
        if modes.ambiguous:
            for k, (g, mw) in enumerate(((modes.first, modes.first_weight), (modes.second, modes.second_weight)), 1):
                self._modes.append((self.float_id, window.time, k, g.lat, g.lon, mw, g.sd_km))
        probs, index = _window_label_probs(step, window, w, label_probs)
        self._labels.extend(label_rows(self.float_id, window, self.beacon_ids, index, probs))
        heard = float(probs.sum()) if probs.size else 0.0  # expected signals from beacons
        self._track[-1] = (*self._track[-1], window_status(step.reseeded_mass, modes.ambiguous, heard))

    def add_steps(
        self,
        steps: Sequence[Step],
        smoothed: Smoothed | None = None,
        label_probs: LabelProbs | None = None,
        extra_cov_km2: NDArray | None = None,
        splits: Sequence[Split | None] | None = None,
    ) -> EstimateBuilder:
        """Summarise every step (`add`): under its filter weights, or under the `smoothed`
        weights (one array per step) with labels from `label_probs`; `extra_cov_km2` (one
        (2, 2) per step) widens the covariances; `splits` (one per step, smoothed only):
        the windows whose filters held the float apart. Returns the builder."""
        extra = [None] * len(steps) if extra_cov_km2 is None else list(extra_cov_km2)
        if smoothed is None:
            for step, cov in zip(steps, extra, strict=True):
                self.add(step, extra_cov_km2=cov)
        else:
            apart = [None] * len(steps) if splits is None else list(splits)
            for step, weights, cov, split in zip(steps, smoothed.weights, extra, apart, strict=True):
                self.add(step, weights, label_probs, cov, split)
        return self

    def rows(self) -> EstimateRows:
        """The rows added so far, for another builder to `extend` with (they pickle: a
        process that summarised some windows sends them to the one that has the others)."""
        return EstimateRows(self._track, self._labels, self._modes, self.window_ess)

    def extend(self, rows: EstimateRows) -> None:
        """Append `rows` of later windows than those added so far."""
        self._track.extend(rows.track)
        self._labels.extend(rows.labels)
        self._modes.extend(rows.modes)
        self.window_ess.extend(rows.window_ess)

    def _modes_of(self, cloud: Cloud, weights: NDArray, extra_cov_km2: NDArray | None, split: Split | None) -> Modes:
        """The cloud's two-mode summary under `weights` (`posterior.two_modes`), by regions
        when the context parts them; of a split window, by the filter each particle is
        nearer, ambiguous, its covariance widened by the split's spread (`add`)."""
        amb = self.ambiguity
        if split is not None:
            return split_modes(cloud, weights, np.zeros((2, 2)) if extra_cov_km2 is None else extra_cov_km2, split)
        return two_modes(
            cloud.lat,
            cloud.lon,
            weights,
            min_weight=amb.min_mode_weight,
            min_separation_km=amb.min_separation_km,
            separation_factor=amb.separation_factor,
            extra_cov_km2=extra_cov_km2,
            groups=None if self.regions is None else self.regions(cloud.particles),
        )

    def result(self) -> Estimate:
        return Estimate(
            kind=self.kind,
            track=_frame(self._track, TRACK_COLUMNS, {"n_signals": "int64", "ambiguous": "bool"}, ("status",)),
            labels=_frame(self._labels, LABEL_COLUMNS, {"rank": "int64"}, ("beacon_id",)),
            modes=_frame(self._modes, MODE_COLUMNS, {"mode": "int64"}),
        )


def split_modes(cloud: Cloud, weights: NDArray, extra_cov_km2: NDArray, split: Split) -> Modes:
    """A split window's two modes (`smoothing.split`): the particles nearer each filter's
    mean, the heavier first (where the join put no weight near a filter's mean, that mode is
    the filter's mean itself, of unknown spread); the whole cloud's covariance widened by
    the split's spread, and its mean the position reported (`Modes.split`)."""
    side = sides(cloud, split)
    parts = []
    for s, (lat, lon) in ((0, split.forward), (1, split.backward)):
        mine = side == s
        mass = float(weights[mine].sum())
        if mass > 0:
            g = summarise(cloud.lat[mine], cloud.lon[mine], weights[mine])
            parts.append((mass, Gaussian2D(g.lat, g.lon, g.cov_km2 + extra_cov_km2)))
        else:
            parts.append((0.0, Gaussian2D(lat, lon, np.full((2, 2), np.nan))))
    (w1, first), (w2, second) = sorted(parts, key=lambda part: -part[0])
    whole = summarise(cloud.lat, cloud.lon, weights)
    whole = Gaussian2D(whole.lat, whole.lon, whole.cov_km2 + extra_cov_km2 + split.spread_km2)
    total = w1 + w2
    return Modes(whole, first, second, w1 / total, w2 / total, split.distance_km, True, split=True)


def _window_label_probs(
    step: Step, window: Window, weights: NDArray, label_probs: LabelProbs | None
) -> tuple[NDArray, NDArray]:
    """The window's association marginals (s, K) and their beacon-table rows: the step's
    filtered ones, or `label_probs` under `weights` (none for a window without signals)."""
    if label_probs is None:
        if step.label_probs is None:
            raise ValueError("the filter kept no association marginals: give label_probs")
        return step.label_probs, step.beacon_index
    if window.n_signals:
        return label_probs(step.cloud.particles, weights, window)
    return np.zeros((0, 0)), np.zeros(0, dtype=np.intp)


def window_status(reseeded_mass: float, ambiguous: bool, heard: float) -> str:
    """What supports a window's position: `recovered` (the filter lost the float and
    re-acquired it here: re-seeded particles carry most of the mass), `ambiguous` (two
    separate modes), `unsupported` (less than one stored signal expected from a beacon: the
    drift model carries the position), else `ok`. The first that applies."""
    if reseeded_mass > 0.5:
        return "recovered"
    if ambiguous:
        return "ambiguous"
    if heard < 1.0:
        return "unsupported"
    return "ok"


def build_estimate(
    float_id: str,
    steps: Sequence[Step],
    beacon_ids: NDArray,
    ambiguity: AmbiguityConfig,
    smoothed: Smoothed | None = None,
    label_probs: LabelProbs | None = None,
    extra_cov_km2: NDArray | None = None,
    regions: Regions | None = None,
) -> Estimate:
    """Tables for every window among `steps` (`EstimateBuilder.add_steps`): filtered, or
    under the `smoothed` weights."""
    builder = EstimateBuilder(float_id, beacon_ids, ambiguity, "filtered" if smoothed is None else "smoothed", regions)
    return builder.add_steps(steps, smoothed, label_probs, extra_cov_km2).result()


def runs_of(times: NDArray[np.datetime64], flags: ArrayLike) -> list[tuple[np.datetime64, np.datetime64]]:
    """Maximal stretches of consecutive flagged windows (e.g. ambiguous ones), as (first, last) times."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], np.asarray(flags, dtype=int), [0]])))
    return [(times[a], times[b - 1]) for a, b in zip(edges[::2], edges[1::2], strict=True)]


def _frame(
    rows: list[tuple], columns: tuple[str, ...], dtypes: dict[str, str], texts: tuple[str, ...] = ()
) -> pd.DataFrame:
    """The table of `rows` with `dtypes` and `time` a datetime.

    With no rows, the other columns get the types rows would give them (`time` in ns,
    `float_id` and `texts` text, the rest float64), not pandas' untyped object columns (an
    empty modes.parquet had null-typed lat and lon)."""
    frame = pd.DataFrame(rows, columns=list(columns))
    if frame.empty:
        text = pd.Series(["x"]).dtype  # what pandas gives a column of text (str, or object before pandas 3)
        named = {"time": "datetime64[ns]", "float_id": text, **dict.fromkeys(texts, text)}
        frame = frame.astype({c: named.get(c, "float64") for c in columns if c not in dtypes})
    frame = frame.astype(dtypes)
    frame["time"] = pd.to_datetime(frame["time"])
    return frame
