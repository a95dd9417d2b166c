"""Reading users' bathymetry grids: the conventions handled, the bad grids refused in one line."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from rafostrack.context.bathymetry import Region, read_bathymetry
from rafostrack.errors import InputError

REGION = Region(-61.0, -55.0, -95.0, -85.0)
LAT = np.arange(-62.0, -54.0 + 1e-9, 0.25)
LON = np.arange(-100.0, -80.0 + 1e-9, 0.25)


def _depth(lat, lon):
    """A smooth sea floor: 3000 m, shoaling to 500 m eastwards."""
    return 3000.0 - 2500.0 * (np.asarray(lon) + 100.0) / 20.0 + 0.0 * np.asarray(lat)


def _write(path: Path, values, *, name="elevation", attrs=None, lat=LAT, lon=LON, dims=("lat", "lon"), coords=True):
    coord_vars = {}
    if coords:
        coord_vars = {
            dims[0]: (dims[0], lat, {"units": "degrees_north"}),
            dims[1]: (dims[1], lon, {"units": "degrees_east"}),
        }
    xr.Dataset({name: (dims, np.asarray(values, dtype=np.float32), attrs or {})}, coords=coord_vars).to_netcdf(path)
    return path


def _water(lat, lon):
    return np.ones(np.shape(lat), dtype=bool)


def _read(path, **kw):
    return read_bathymetry(path, REGION, 0.25, is_water=_water, **kw)


@pytest.fixture
def grid_values():
    lon2, lat2 = np.meshgrid(LON, LAT)
    return _depth(lat2, lon2)


def test_heights_and_depths_read_alike(tmp_path, grid_values):
    up = _read(_write(tmp_path / "up.nc", -grid_values, attrs={"positive": "up"}))
    down = _read(_write(tmp_path / "down.nc", grid_values, name="depth", attrs={"positive": "down"}))
    named = _read(_write(tmp_path / "z.nc", -grid_values, name="z"))  # ETOPO: z, no attribute
    by_data = _read(_write(tmp_path / "band.nc", grid_values, name="topo_grid"))  # unknown name: the data say
    assert (up.sign, down.sign, named.sign, by_data.sign) == ("up", "down", "up", "down")
    for other in (down, named, by_data):
        np.testing.assert_allclose(other.depth_m, up.depth_m)
    lon2, lat2 = np.meshgrid(up.lon, up.lat)
    np.testing.assert_allclose(up.depth_m, _depth(lat2, lon2), atol=1e-2)
    assert up.lat.min() <= REGION.lat_min and up.lat.max() >= REGION.lat_max


def test_sign_contradicted_or_unknown_is_one_clear_line(tmp_path, grid_values):
    wrong = _write(tmp_path / "wrong.nc", -grid_values, name="depth", attrs={"positive": "down"})
    with pytest.raises(InputError, match=r"wrong.nc: .*positive down.*most ocean cells .* are negative.*depth_sign"):
        _read(wrong)
    assert _read(wrong, sign="up").sign == "up"  # the config's word, and the data agree
    unknown = _write(tmp_path / "unknown.nc", grid_values, name="topo_grid")
    with pytest.raises(InputError, match=r"cannot tell .*depth_sign"):
        read_bathymetry(unknown, REGION, 0.25)  # no land mask to look at
    with pytest.raises(InputError, match=r"wrong.nc: .* from \[context\] depth_sign"):
        _read(wrong, sign="down")


def test_missing_coordinates_and_unreadable_files(tmp_path, grid_values):
    bare = _write(tmp_path / "bare.nc", grid_values, dims=("y", "x"), coords=False)
    with pytest.raises(InputError, match=r"bare.nc: variable 'elevation' over \(y, x\) has no latitude/longitude"):
        _read(bare)
    (tmp_path / "text.nc").write_text("not a grid\n")
    with pytest.raises(InputError, match=r"text.nc: cannot read as a NetCDF grid"):
        _read(tmp_path / "text.nc")
    with pytest.raises(InputError, match=r"missing.nc: bathymetry file not found"):
        _read(tmp_path / "missing.nc")
    with pytest.raises(InputError) as caught:
        _read(bare)
    assert "\n" not in str(caught.value)


def test_descending_latitude_and_0_360_longitudes(tmp_path, grid_values):
    base = _read(_write(tmp_path / "base.nc", -grid_values))
    flipped = _read(_write(tmp_path / "flip.nc", -grid_values[::-1], lat=LAT[::-1]))
    np.testing.assert_allclose(flipped.depth_m, base.depth_m)
    np.testing.assert_allclose(flipped.lat, base.lat)
    shifted = _read(_write(tmp_path / "east.nc", -grid_values, lon=LON + 360.0))
    np.testing.assert_allclose(shifted.depth_m, base.depth_m)
    np.testing.assert_allclose(shifted.lon, base.lon)


def test_a_region_across_the_grids_seam_is_read_in_two_pieces(tmp_path):
    lon = np.arange(0.0, 360.0, 1.0)  # a global 0..360 grid; the region straddles 0 E
    lat = np.arange(-10.0, 10.1, 1.0)
    lon2, _lat2 = np.meshgrid(lon, lat)
    east = np.where(lon2 > 180, lon2 - 360, lon2)
    path = _write(tmp_path / "global.nc", -(4000.0 + 10.0 * east), lat=lat, lon=lon)
    out = read_bathymetry(path, Region(-5.0, 5.0, -20.0, 20.0), 1.0, is_water=_water)
    assert np.all(np.diff(out.lon) > 0) and out.lon[0] < 0 < out.lon[-1]
    np.testing.assert_allclose(out.depth_m[0], 4000.0 + 10.0 * out.lon)


def test_a_grid_not_covering_the_mission_is_refused(tmp_path, grid_values):
    path = _write(tmp_path / "small.nc", -grid_values)
    with pytest.raises(InputError, match=r"small.nc: the grid covers latitude -62..-54.*launch position \(-40, -90\)"):
        read_bathymetry(path, REGION, 0.25, must_cover=((-40.0, -90.0, "launch position"),), is_water=_water)


def test_finer_cells_are_averaged_with_their_spread(tmp_path):
    lat = np.arange(-60.0, -58.0, 0.25) + 0.125
    lon = np.arange(-91.0, -89.0, 0.25) + 0.125
    values = np.arange(len(lat) * len(lon), dtype=float).reshape(len(lat), len(lon)) + 1000.0
    path = _write(tmp_path / "fine.nc", values, name="depth", lat=lat, lon=lon)
    out = read_bathymetry(path, Region(-60.0, -58.0, -91.0, -89.0), 0.5, is_water=_water)
    assert out.depth_m.shape == (4, 4)
    np.testing.assert_allclose(out.depth_m[0, 0], values[:2, :2].mean())
    np.testing.assert_allclose(out.spread_m[0, 0], values[:2, :2].std())
    np.testing.assert_allclose(out.lat[:2], [-59.75, -59.25])
