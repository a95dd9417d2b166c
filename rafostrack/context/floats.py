"""Context for RAFOS floats: CF = P(the sea floor is deeper than the float | grid, land mask),
per cell, and the factor it puts on each particle move in the tracker's filter.

The network (exact inference, `bayesnet`), per cell:
    water W (sea, land)            -> land mask L (sea, land): wrong with prob. land_mask_error
    W                              -> true depth D (50 m bins; uniform over -500..0 m on land,
                                      0..8000 m at sea)
    D, grid sd class U             -> grid depth G: discretised N(D, U^2 + (r D)^2)
    D, float depth F               -> M = the float can be here: P(M | D, F) = Phi((D - F) / sd_F)
    CF = P(M = true | L, G, U), with F fixed at the float's depth (its prior a point mass).
The depth-uncertainty model: the grid's error has sd sqrt(s0^2 + (r D)^2 + (h slope)^2 +
spread^2), s0 = depth_sd_m, r = depth_sd_fraction, h = depth_horizontal_km (a horizontal
misplacement of the soundings times the local slope, m/km), spread = sd of the finer source
cells inside a context cell; U is that sd without the (r D) term, in 24 classes from 5 m to
4 km (log-spaced). Without a grid (land only) the network is W -> L, M = (W = sea); cells the
grid lacks take that CF. A stated model, not a fitted one: its keys are in `[context]`.

The factor (`ContextFactor`, a `likelihoods.MoveFactor`): the paper's cell-entry rule
(`rules.entry_log_factor`) along the straight move between two filter steps. Adapted to the
float filter: every step has an observation (a listening window, even an empty one, carries
the likelihood of hearing what was heard; or a position fix), so the rule's branch "entered
a new area with an observation" always applies and the CF is multiplied into the weight;
the "resample by CF without an observation" branch does not arise (in distribution it is the
same multiplication followed by resampling, which the filter does when the ESS drops). A
multi-day gap is one motion step: the straight path crosses every area between the two
positions, each entered area counting once, so a particle cannot jump a ridge in a gap.
Areas: connected cells of like CF (bands at `BAND_EDGES`): a grid's depth errors are
correlated over several cells, so neighbouring cells of like CF are one area A_k in the
paper's sense and a float drifting along a slope is not charged at every cell.
A forbidden move gets log weight `FORBIDDEN_LOG_WEIGHT` (not -inf), so that if every particle
moved illegally the filter still has finite weights.
"""

from __future__ import annotations

import functools
import math
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.special import ndtr

from ..config import Config, ContextConfig
from ..domain import BeaconTable, FloatInfo, Particles
from ..errors import InputError
from ..likelihoods.base import MoveFactor
from ..model.geodesy import wrap_lon
from .bathymetry import Bathymetry, Region, read_bathymetry
from .bayesnet import DiscreteBayesNet, Node, binary_cpt
from .grid import ContextGrid, ContextModel
from .land import land_mask
from .rules import entry_log_factor, naive_log_factor

DEPTH_CENTRES_M = np.arange(-500.0, 8000.0 + 1.0, 50.0)
DRY = DEPTH_CENTRES_M <= 0.0
SD_CLASSES_M = np.geomspace(5.0, 4000.0, 24)
BAND_EDGES = (0.02, 0.25, 0.5, 0.75, 0.98)
FORBIDDEN_LOG_WEIGHT = -1.0e5
KM_PER_DEG = 111.2
_CONTEXTS: OrderedDict[str, FloatContext] = OrderedDict()  # the latest context per float (for plots)
_KEEP = 8


def _depth_edges() -> NDArray[np.float64]:
    mid = 0.5 * (DEPTH_CENTRES_M[1:] + DEPTH_CENTRES_M[:-1])
    return np.concatenate([[-np.inf], mid, [np.inf]])


def float_network(settings: ContextConfig, float_depth_m: float, *, grid: bool = True) -> DiscreteBayesNet:
    """The network of the module docstring (with `grid=False`: land only)."""
    eps = settings.land_mask_error
    water = Node("water", ("sea", "land"), (), np.array([0.5, 0.5]))
    mask = Node("land_mask", ("sea", "land"), ("water",), np.array([[1 - eps, eps], [eps, 1 - eps]]))
    if not grid:
        mobile = Node("mobile", ("false", "true"), ("water",), binary_cpt(np.array([1.0, 0.0])))
        return DiscreteBayesNet([water, mask, mobile])
    depth_given_water = np.stack([np.where(DRY, 0.0, 1.0), np.where(DRY, 1.0, 0.0)])
    depth_given_water /= depth_given_water.sum(axis=1, keepdims=True)
    sd = np.sqrt(
        SD_CLASSES_M[None, :] ** 2 + (settings.depth_sd_fraction * np.clip(DEPTH_CENTRES_M, 0, None))[:, None] ** 2
    )
    cdf = ndtr((_depth_edges()[None, None, :] - DEPTH_CENTRES_M[:, None, None]) / sd[:, :, None])
    grid_given = np.diff(cdf, axis=-1)  # (D, U, G)
    grid_given /= grid_given.sum(axis=-1, keepdims=True)
    p_mobile = np.where(DRY, 0.0, ndtr((DEPTH_CENTRES_M - float_depth_m) / settings.float_depth_sd_m))[:, None]
    return DiscreteBayesNet(
        [
            water,
            mask,
            Node(
                "sd_class",
                tuple(f"{s:.0f}m" for s in SD_CLASSES_M),
                (),
                np.full(len(SD_CLASSES_M), 1.0 / len(SD_CLASSES_M)),
            ),
            Node("depth", tuple(f"{d:g}" for d in DEPTH_CENTRES_M), ("water",), depth_given_water),
            Node("grid_depth", tuple(f"{d:g}" for d in DEPTH_CENTRES_M), ("depth", "sd_class"), grid_given),
            Node("float_depth", (f"{float_depth_m:g} m",), (), np.ones(1)),
            Node("mobile", ("false", "true"), ("depth", "float_depth"), binary_cpt(p_mobile)),
        ]
    )


def sd_class(sd_m: NDArray[np.float64]) -> NDArray[np.intp]:
    """The nearest class of `SD_CLASSES_M` (in log) of each sd."""
    log_classes = np.log(SD_CLASSES_M)
    return np.abs(np.log(np.clip(sd_m, 1e-3, None))[..., None] - log_classes).argmin(axis=-1)


def depth_bin(depth_m: NDArray[np.float64]) -> NDArray[np.intp]:
    """The bin of `DEPTH_CENTRES_M` holding each depth (NaN -> 0; clipped at both ends)."""
    return np.clip(np.digitize(np.nan_to_num(depth_m), _depth_edges()[1:-1]), 0, len(DEPTH_CENTRES_M) - 1)


def slope_m_per_km(bathy: Bathymetry) -> NDArray[np.float64]:
    """|grad depth| (m/km) from the cell means (central differences; NaN next to missing cells)."""
    lat_km = bathy.dlat * KM_PER_DEG
    lon_km = bathy.dlon * KM_PER_DEG * np.cos(np.radians(bathy.lat))[:, None]
    d_lat, d_lon = np.gradient(bathy.depth_m) if min(bathy.depth_m.shape) > 1 else (0.0, 0.0)
    return np.hypot(np.asarray(d_lat) / lat_km, np.asarray(d_lon) / lon_km)


def depth_sd_m(bathy: Bathymetry, settings: ContextConfig) -> NDArray[np.float64]:
    """The grid error's sd without its relative term (module docstring)."""
    slope = np.nan_to_num(slope_m_per_km(bathy))
    horizontal = settings.depth_horizontal_km * slope
    return np.sqrt(settings.depth_sd_m**2 + horizontal**2 + np.nan_to_num(bathy.spread_m) ** 2)


@dataclass
class FloatContext:
    """One float's context: the grid of CF, and what it was made from (for plots)."""

    grid: ContextGrid
    float_depth_m: float
    bathymetry: Bathymetry | None
    land: bool


def mission_region(info: FloatInfo, beacons: BeaconTable, margin_deg: float) -> Region:
    """The box around the launch and end fixes and the beacons, plus a margin; longitudes
    unwrapped around the launch."""
    lats = [info.launch_lat, *np.asarray(beacons.lat, dtype=float)]
    lons = [info.launch_lon, *np.asarray(beacons.lon, dtype=float)]
    if info.has_end_fix:
        lats.append(info.end_lat)
        lons.append(info.end_lon)
    ref = float(info.launch_lon)
    unwrapped = ref + wrap_lon(np.asarray(lons, dtype=float) - ref)
    lon_min, lon_max = float(unwrapped.min()) - margin_deg, float(unwrapped.max()) + margin_deg
    if lon_max - lon_min >= 360.0:
        lon_min, lon_max = ref - 180.0, ref + 180.0
    return Region(max(min(lats) - margin_deg, -90.0), min(max(lats) + margin_deg, 90.0), lon_min, lon_max)


def build_context(
    settings: ContextConfig, region: Region, float_depth_m: float, must_cover: tuple = ()
) -> FloatContext:
    """The context grid over `region` (module docstring)."""
    mask = land_mask(region.lat_min, region.lat_max)
    bathy = None
    if settings.bathymetry:
        bathy = read_bathymetry(
            Path(settings.bathymetry), region, settings.cell_arcmin / 60.0, sign=settings.depth_sign,
            must_cover=must_cover, is_water=mask.is_water,
        )  # fmt: skip
        lat, lon = bathy.lat, bathy.lon
    else:
        cell = settings.cell_arcmin / 60.0
        lat = np.arange(region.lat_min + cell / 2, region.lat_max, cell)
        lon = np.arange(region.lon_min + cell / 2, region.lon_max, cell)
    lon2, lat2 = np.meshgrid(lon, lat)
    mask_land = (~mask.is_water(lat2, lon2)).astype(np.intp)
    land_only = ContextModel(float_network(settings, float_depth_m, grid=False), "mobile", ("land_mask",))
    cf = land_only.cf({"land_mask": mask_land}) if settings.land else np.ones(lat2.shape)
    if bathy is not None:
        given = ("land_mask", "grid_depth", "sd_class") if settings.land else ("grid_depth", "sd_class")
        model = ContextModel(float_network(settings, float_depth_m), "mobile", given)
        evidence = {
            "land_mask": mask_land,
            "grid_depth": depth_bin(bathy.depth_m),
            "sd_class": sd_class(depth_sd_m(bathy, settings)),
        }
        known = np.isfinite(bathy.depth_m)
        cf = np.where(known, model.cf({k: evidence[k] for k in given}), cf)
    dlat = float(lat[1] - lat[0]) if len(lat) > 1 else settings.cell_arcmin / 60.0
    dlon = float(lon[1] - lon[0]) if len(lon) > 1 else settings.cell_arcmin / 60.0
    grid = ContextGrid(
        float(lon[0]) - dlon / 2, float(lat[0]) - dlat / 2, dlon, dlat, cf, band_edges=BAND_EDGES, wrap_x=360.0
    )
    return FloatContext(grid, float_depth_m, bathy, settings.land)


@functools.lru_cache(maxsize=4)
def _cached_context(settings: ContextConfig, region: Region, float_depth_m: float, must_cover: tuple,
                    stamp: tuple) -> FloatContext:  # fmt: skip
    del stamp  # part of the key only: the file's size and modification time
    return build_context(settings, region, float_depth_m, must_cover)


def float_depth(info: FloatInfo, settings: ContextConfig) -> float:
    """The float's depth: floats.csv's depth_m, else [context] float_depth_m; an error when a
    bathymetry grid needs it and neither is given."""
    if math.isfinite(info.depth_m):
        return float(info.depth_m)
    if settings.float_depth_m > 0:
        return float(settings.float_depth_m)
    if settings.bathymetry:
        raise InputError(
            f"float {info.float_id!r}: the bathymetry constraint needs the float's depth; expected a depth_m column "
            "in floats.csv or [context] float_depth_m in the config"
        )
    return math.nan


def context_for(config: Config, beacons: BeaconTable, info: FloatInfo) -> FloatContext | None:
    """The float's context (None when `[context]` asks for none), cached per process."""
    settings = config.context
    if not (settings.land or settings.bathymetry):
        return None
    depth = float_depth(info, settings)
    region = mission_region(info, beacons, settings.margin_deg)
    cover = [(info.launch_lat, info.launch_lon, "launch position")]
    if info.has_end_fix:
        cover.append((info.end_lat, info.end_lon, "end position"))
    stamp: tuple[Any, ...] = ()
    if settings.bathymetry:
        path = Path(settings.bathymetry)
        stat = path.stat() if path.is_file() else None
        stamp = (str(path.resolve()), stat.st_size, stat.st_mtime_ns) if stat else (str(path),)
    context = _cached_context(settings, region, depth, tuple(cover), stamp)
    _CONTEXTS[info.float_id] = context
    _CONTEXTS.move_to_end(info.float_id)
    while len(_CONTEXTS) > _KEEP:
        _CONTEXTS.popitem(last=False)
    return context


def float_context(float_id: str) -> FloatContext | None:
    """The context last built for this float in this process (for the track map), if any."""
    return _CONTEXTS.get(float_id)


class ContextFactor(MoveFactor):
    """log CF of the areas a particle enters on its move (module docstring), or with
    rule = "naive" log CF of where it is after every move."""

    def __init__(self, grid: ContextGrid, rule: str = "entry"):
        if rule not in ("entry", "naive"):
            raise ValueError(f"rule must be entry or naive, got {rule!r}")
        self.grid = grid
        self.rule = rule

    def log_weight(self, before: Particles, after: Particles, observation: Any) -> NDArray[np.float64]:
        if self.rule == "naive":
            log_cf = naive_log_factor(self.grid, after.lon, after.lat)
        else:
            log_cf, _ = entry_log_factor(self.grid, before.lon, before.lat, after.lon, after.lat)
        return np.maximum(log_cf, FORBIDDEN_LOG_WEIGHT)

    def regions(self, particles: Particles) -> NDArray[np.int64] | None:
        return self.grid.region_at(particles.lon, particles.lat)


def context_factors(config: Config, beacons: BeaconTable, info: FloatInfo) -> tuple[MoveFactor, ...]:
    """The move factors `[context]` asks for (none when it asks for no context)."""
    context = context_for(config, beacons, info)
    if context is None:
        return ()
    return (ContextFactor(context.grid, config.context.rule),)
