"""A user's bathymetry grid (GEBCO, ETOPO or any CF-convention NetCDF), read with xarray.

What is accepted, and what is a one-line `InputError` naming the file:
- the variable: the one 2-D data variable, or among several the one named (or with the
  standard_name of) an elevation or depth (`elevation`, `z`, `depth`, `bathymetry`, ...);
- coordinates: 1-D latitude and longitude coordinate variables recognised by their units
  (degrees_north / degrees_east), standard_name or name (lat, latitude, lon, longitude, and
  x / y only with degree units); none (e.g. an old GMT grid with x_range / spacing), 2-D
  (curvilinear) or non-monotonic ones are errors;
- latitudes descending (ETOPO 2022 tiles, many GMT grids) are flipped; longitudes in 0..360 or
  -180..180 are both read, the region asked for being moved to the grid's convention (a
  region across the grid's seam is read in two pieces);
- the sign: heights (positive up: GEBCO's `elevation`, ETOPO's `z`) or depths (positive
  down). The `positive` attribute decides, else the standard_name or name, else the data
  (most water cells of the land mask are below sea level); `depth_sign` in the config
  overrides all that; a stated sign that the data contradict (most water cells above sea
  level) is an error;
- coverage: a grid that does not contain the float's launch (and end) position is an error;
  elsewhere in the region, cells the grid lacks (or fills with missing values) are NaN.

The result is the sea-floor depth, positive down (land negative), averaged onto a regular
grid of at most the requested cell size together with the spread of the finer cells inside
each cell (used by the depth-uncertainty model, `floats.depth_sd_m`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError

ELEVATION_NAMES = ("elevation", "z", "topo", "topography", "height", "altitude", "elev", "band1")
DEPTH_NAMES = ("depth", "bathymetry", "bathy", "sea_floor_depth", "water_depth")
UP_STANDARD_NAMES = ("height_above_reference_ellipsoid", "height_above_mean_sea_level", "altitude",
                     "surface_altitude", "height", "height_above_geoid", "bedrock_altitude")  # fmt: skip
DOWN_STANDARD_NAMES = ("sea_floor_depth", "sea_floor_depth_below_geoid", "sea_floor_depth_below_sea_surface",
                       "sea_floor_depth_below_mean_sea_level", "depth")  # fmt: skip
_MAJORITY = 0.8  # share of water cells that must agree on the sign
_ROW_BLOCK_CELLS = 1 << 23  # fine cells read at once


@dataclass(frozen=True)
class Region:
    """A latitude-longitude box; lon_min < lon_max, possibly beyond [-180, 180] (unwrapped)."""

    lat_min: float
    lat_max: float
    lon_min: float
    lon_max: float


@dataclass(frozen=True)
class Bathymetry:
    """Sea-floor depth (m, positive down) on a regular grid: cell (i, j) has its centre at
    (lat[i], lon[j]); `spread_m` is the sd of the finer source cells inside it (0 when the
    source is not finer). lon is ascending, in the region's frame; NaN = no data."""

    lat: NDArray[np.float64]
    lon: NDArray[np.float64]
    depth_m: NDArray[np.float64]
    spread_m: NDArray[np.float64]
    source: str
    variable: str
    sign: str  # how the file was read: "up" (heights) or "down" (depths)

    @property
    def dlat(self) -> float:
        return float(self.lat[1] - self.lat[0]) if len(self.lat) > 1 else 1.0

    @property
    def dlon(self) -> float:
        return float(self.lon[1] - self.lon[0]) if len(self.lon) > 1 else 1.0


def _fail(path: Path, what: str) -> InputError:
    return InputError(f"{path}: {what}")


def _open(path: Path):
    import xarray as xr

    if not path.is_file():
        raise _fail(path, "bathymetry file not found (expected a NetCDF grid, e.g. GEBCO or ETOPO)")
    try:
        return xr.open_dataset(path, decode_times=False, mask_and_scale=True)
    except Exception as exc:  # xarray raises many kinds for a file it cannot read
        reason = " ".join(str(exc).splitlines())[:160]
        raise _fail(path, f"cannot read as a NetCDF grid ({type(exc).__name__}: {reason})") from None


def _pick_variable(path: Path, ds) -> str:
    grids = [str(k) for k, v in ds.data_vars.items() if v.ndim == 2]
    if not grids:
        raise _fail(path, "no 2-D data variable (expected an elevation or depth grid over latitude and longitude)")
    if len(grids) == 1:
        return grids[0]
    known = [*ELEVATION_NAMES, *DEPTH_NAMES]
    named = [g for g in grids if g.lower() in known or str(ds[g].attrs.get("standard_name", "")).lower() in
             (*UP_STANDARD_NAMES, *DOWN_STANDARD_NAMES)]  # fmt: skip
    if len(named) == 1:
        return named[0]
    raise _fail(path, f"several 2-D variables ({', '.join(grids)}); expected one named elevation, z or depth")


def _is_axis(coord, axis: str) -> bool:
    """Whether a coordinate variable is latitude (axis 'lat') or longitude ('lon')."""
    units = str(coord.attrs.get("units", "")).lower().replace(" ", "_")
    std = str(coord.attrs.get("standard_name", "")).lower()
    name = str(coord.name).lower()
    if axis == "lat":
        return (
            units in ("degrees_north", "degree_north", "degrees_n", "degree_n")
            or std == "latitude"
            or (name in ("lat", "latitude", "nav_lat") and "m" != units)
        )
    return (
        units in ("degrees_east", "degree_east", "degrees_e", "degree_e")
        or std == "longitude"
        or (name in ("lon", "long", "longitude", "nav_lon") and "m" != units)
    )


def _coordinates(path: Path, ds, name: str) -> tuple[str, str, NDArray, NDArray]:
    """(lat dim, lon dim, lat values, lon values) of variable `name`."""
    var = ds[name]
    found: dict[str, str] = {}
    for dim in var.dims:
        if dim not in ds.coords or ds[dim].ndim != 1:
            continue
        for axis in ("lat", "lon"):
            if axis not in found and _is_axis(ds[dim], axis):
                found[axis] = str(dim)
    if len(found) < 2:
        dims = ", ".join(str(d) for d in var.dims)
        two_d = [c for c in ds.coords if ds[c].ndim == 2]
        extra = f" (2-D coordinates {', '.join(map(str, two_d))} are not supported)" if two_d else ""
        raise _fail(
            path,
            f"variable {name!r} over ({dims}) has no latitude/longitude coordinates{extra}; expected 1-D coordinate "
            "variables such as lat (units degrees_north) and lon (units degrees_east), as in GEBCO or ETOPO grids",
        )
    lat = np.asarray(ds[found["lat"]].values, dtype=float)
    lon = np.asarray(ds[found["lon"]].values, dtype=float)
    for axis, values in (("latitude", lat), ("longitude", lon)):
        step = np.diff(values)
        if len(values) < 2 or not np.all(np.isfinite(values)) or not (np.all(step > 0) or np.all(step < 0)):
            raise _fail(path, f"{axis} coordinate of {name!r} is not strictly monotonic (or has fewer than 2 values)")
    if lat.min() < -90.5 or lat.max() > 90.5 or lon.min() < -360 or lon.max() > 720:
        raise _fail(path, f"coordinates of {name!r} are not in degrees (latitude {lat.min():g}..{lat.max():g})")
    return found["lat"], found["lon"], lat, lon


def stated_sign(var) -> str | None:
    """'up' or 'down' from the variable's attributes or name; None when they do not say."""
    positive = str(var.attrs.get("positive", "")).strip().lower()
    if positive in ("up", "down"):
        return positive
    std = str(var.attrs.get("standard_name", "")).lower()
    if std in UP_STANDARD_NAMES:
        return "up"
    if std in DOWN_STANDARD_NAMES:
        return "down"
    name = str(var.name).lower()
    if name in ELEVATION_NAMES:
        return "up"
    if name in DEPTH_NAMES:
        return "down"
    return None


def _runs(index: NDArray[np.intp]) -> list[slice]:
    """Contiguous runs of sorted indices, as slices."""
    if len(index) == 0:
        return []
    breaks = np.flatnonzero(np.diff(index) != 1)
    starts = np.concatenate([[index[0]], index[breaks + 1]])
    stops = np.concatenate([index[breaks], [index[-1]]]) + 1
    return [slice(int(a), int(b)) for a, b in zip(starts, stops, strict=True)]


def _block_stats(values: NDArray, k_lat: int, k_lon: int) -> tuple[NDArray, NDArray]:
    """Mean and sd (ignoring NaN) over k_lat x k_lon blocks of `values` (whole blocks only)."""
    ny, nx = values.shape[0] // k_lat, values.shape[1] // k_lon
    blocks = values[: ny * k_lat, : nx * k_lon].reshape(ny, k_lat, nx, k_lon)
    count = np.sum(np.isfinite(blocks), axis=(1, 3))
    total = np.nansum(blocks, axis=(1, 3))
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(count > 0, total / np.maximum(count, 1), np.nan)
        square = np.nansum(blocks * blocks, axis=(1, 3))
        var = np.where(count > 0, square / np.maximum(count, 1) - mean * mean, np.nan)
    return mean, np.sqrt(np.clip(var, 0.0, None))


def read_bathymetry(
    path: Path,
    region: Region,
    cell_deg: float,
    *,
    sign: str = "auto",
    must_cover: tuple[tuple[float, float, str], ...] = (),
    is_water=None,
) -> Bathymetry:
    """The grid's sea-floor depth over `region`, averaged onto cells of about `cell_deg`
    (module docstring). `must_cover`: (lat, lon, what) points the grid must contain;
    `is_water(lat, lon)`: the land mask, to check or find the sign."""
    path = Path(path)
    ds = _open(path)
    try:
        name = _pick_variable(path, ds)
        lat_dim, lon_dim, lat, lon = _coordinates(path, ds, name)
        dlat, dlon = abs(lat[1] - lat[0]), abs(lon[1] - lon[0])
        west = 0.5 * (region.lon_min + region.lon_max) - 180.0
        lon_frame = west + np.mod(lon - west, 360.0)
        span = f"latitude {lat.min():g}..{lat.max():g}, longitude {lon.min():g}..{lon.max():g}"
        _check_cover(path, lat, lon, lon_frame, west, must_cover, span)
        rows = np.flatnonzero((lat >= region.lat_min - dlat) & (lat <= region.lat_max + dlat))
        cols = np.flatnonzero((lon_frame >= region.lon_min - dlon) & (lon_frame <= region.lon_max + dlon))
        if len(rows) < 2 or len(cols) < 2:
            raise _fail(path, f"the grid covers {span}, not the mission's region; expected a grid covering the mission")
        k_lat = max(1, round(cell_deg / dlat))
        k_lon = max(1, round(cell_deg / dlon))
        order = np.argsort(lon_frame[cols], kind="stable")
        lon_sorted = lon_frame[cols][order]
        keep = np.concatenate([[True], np.diff(lon_sorted) > 1e-9])  # 0 and 360 both present: one column
        lat_sorted = np.sort(lat[rows])
        var = ds[name].transpose(lat_dim, lon_dim)
        values, spread = _block_average(var, lat, rows, cols, (order, keep), (k_lat, k_lon), (lat_dim, lon_dim))
        attrs_var = ds[name]
    finally:
        ds.close()
    ny, nx = values.shape
    lat_c = lat_sorted[: ny * k_lat].reshape(ny, k_lat).mean(axis=1)
    lon_c = lon_sorted[keep][: nx * k_lon].reshape(nx, k_lon).mean(axis=1)
    read_sign = _decide_sign(path, name, values, lat_c, lon_c, sign, attrs_var, is_water)
    depth = -values if read_sign == "up" else values
    return Bathymetry(lat_c, lon_c, depth, spread, str(path), name, read_sign)


def _check_cover(
    path: Path,
    lat: NDArray,
    lon: NDArray,
    lon_frame: NDArray,
    west: float,
    must_cover: tuple[tuple[float, float, str], ...],
    span: str,
) -> None:
    """InputError unless every (lat, lon, what) of `must_cover` is within half a grid step
    of the grid (longitudes compared in the frame starting at `west`)."""
    dlat, dlon = abs(lat[1] - lat[0]), abs(lon[1] - lon[0])
    for p_lat, p_lon, what in must_cover:
        p = west + np.mod(p_lon - west, 360.0)
        inside_lat = lat.min() - dlat / 2 <= p_lat <= lat.max() + dlat / 2
        inside_lon = np.any(np.abs(lon_frame - p) <= dlon / 2 + 1e-9) or lon.max() - lon.min() >= 360 - 1.5 * dlon
        if not (inside_lat and inside_lon):
            raise _fail(
                path,
                f"the grid covers {span}, which does not contain the float's {what} ({p_lat:g}, {p_lon:g}); "
                "expected a grid covering the mission",
            )


def _block_average(
    var,
    lat: NDArray,
    rows: NDArray[np.intp],
    cols: NDArray[np.intp],
    columns: tuple[NDArray[np.intp], NDArray[np.bool_]],
    cell: tuple[int, int],
    dims: tuple[str, str],
) -> tuple[NDArray, NDArray]:
    """Mean and sd of the grid `var` (lat, lon) over cells of k_lat x k_lon points of its
    `rows` x `cols`, rows south to north and the columns put in frame order and
    deduplicated by `columns` = (order, keep); read a band of rows at a time."""
    (order, keep), (k_lat, k_lon), (lat_dim, lon_dim) = columns, cell, dims
    pieces_per_read = max(1, _ROW_BLOCK_CELLS // (k_lat * len(cols))) * k_lat
    means, spreads = [], []
    row_order = rows if lat[1] > lat[0] else rows[::-1]  # rows south to north
    for start in range(0, len(row_order) - k_lat + 1, pieces_per_read):
        chunk_rows = np.sort(row_order[start : start + pieces_per_read])
        if len(chunk_rows) < k_lat:
            break
        parts = [var.isel({lat_dim: slice(int(chunk_rows[0]), int(chunk_rows[-1]) + 1), lon_dim: s}).values
                 for s in _runs(cols)]  # fmt: skip
        raw = np.concatenate(parts, axis=1).astype(float)[:, order][:, keep]
        if lat[1] < lat[0]:
            raw = raw[::-1]
        whole = (len(raw) // k_lat) * k_lat
        mean, spread = _block_stats(raw[:whole], k_lat, k_lon)
        means.append(mean)
        spreads.append(spread)
    return np.concatenate(means), np.concatenate(spreads)


def _decide_sign(path: Path, name: str, values, lat_c, lon_c, setting: str, var, is_water) -> str:
    """'up' or 'down' (module docstring): the config, else the attributes, else the data."""
    from_data = None
    if is_water is not None:
        lon2, lat2 = np.meshgrid(lon_c, lat_c)
        water = is_water(lat2, lon2) & np.isfinite(values) & (values != 0)
        if water.sum() >= 10:
            below = float(np.mean(values[water] < 0))
            from_data = "up" if below >= _MAJORITY else "down" if below <= 1 - _MAJORITY else None
    stated = setting if setting in ("up", "down") else stated_sign(var)
    where = "[context] depth_sign" if setting in ("up", "down") else "its attributes"
    if stated is not None and from_data is not None and stated != from_data:
        said = "heights (positive up)" if stated == "up" else "depths (positive down)"
        found = "positive" if from_data == "down" else "negative"
        raise _fail(
            path,
            f"variable {name!r} is read as {said} from {where}, but most ocean cells (land mask) are {found}; "
            "expected depth_sign in [context] to say how the grid is signed (up: heights, down: depths)",
        )
    decided = stated or from_data
    if decided is None:
        raise _fail(
            path,
            f"cannot tell whether {name!r} holds heights (positive up) or depths (positive down): no 'positive' "
            'attribute and the ocean cells do not say; expected [context] depth_sign = "up" or "down"',
        )
    return decided
