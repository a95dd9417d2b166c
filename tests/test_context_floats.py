"""Context for floats: the network's CF against its closed form, the move factor, the
configuration, and the must-show case: a float along a ridge with a gap."""

from __future__ import annotations

import dataclasses
import json
import shutil

import numpy as np
import pytest
from click.testing import CliRunner
from scipy.stats import norm

from papers.context import floats_ridge
from rafostrack.cli import main
from rafostrack.config import load_config
from rafostrack.context.floats import (
    FORBIDDEN_LOG_WEIGHT,
    SD_CLASSES_M,
    ContextFactor,
    context_factors,
    depth_bin,
    float_network,
)
from rafostrack.context.grid import ContextGrid, ContextModel
from rafostrack.domain import Particles
from rafostrack.errors import InputError
from rafostrack.sim.scenarios import synthetic_scenario


def _settings(**context):
    return load_config(overrides={"context": context}).context


def test_cf_is_the_probability_that_the_sea_floor_is_below_the_float():
    """Without the relative error term and the land mask, P(M | G, U) is the closed form
    Phi((G - F) / sqrt(U^2 + sd_F^2)) (flat prior on the true depth at sea)."""
    settings = _settings(depth_sd_fraction=0.0, float_depth_sd_m=50.0)
    model = ContextModel(float_network(settings, 1000.0), "mobile", ("grid_depth", "sd_class"))
    grid_depth = np.array([600.0, 900.0, 1000.0, 1100.0, 1500.0, 3000.0])
    for k in (4, 8, 11):
        u = SD_CLASSES_M[k]
        cf = model.cf({"grid_depth": depth_bin(grid_depth), "sd_class": np.full(len(grid_depth), k)})
        expected = norm.cdf((grid_depth - 1000.0) / np.hypot(u, 50.0))
        np.testing.assert_allclose(cf, expected, atol=0.02)
    land = ContextModel(float_network(settings, 1000.0, grid=False), "mobile", ("land_mask",))
    np.testing.assert_allclose(land.cf({"land_mask": np.array([0, 1])}), [0.999, 0.001])
    both = ContextModel(float_network(settings, 1000.0), "mobile", ("land_mask", "grid_depth", "sd_class"))
    said_land = both.cf({"land_mask": np.array([1, 1]), "grid_depth": depth_bin(np.array([3000.0, 1200.0])),
                         "sd_class": np.array([10, 18])})  # fmt: skip
    # The mask says land: a grid 3000 m deep (sd ~90 m) outweighs its 0.1% error rate; a grid
    # at 1200 m with sd ~700 m does not, and the mask's word decides.
    assert said_land[0] > 0.99 and said_land[1] < 0.05


def test_move_factor_charges_entries_and_stays_finite():
    cf = np.ones((10, 10))
    cf[:, 5:] = 0.0
    grid = ContextGrid(-5.0, -5.0, 1.0, 1.0, cf, wrap_x=360.0)  # lon -5..5, lat -5..5
    before = Particles(np.zeros(3), np.array([-4.0, -4.0, 1.0]))
    after = Particles(np.zeros(3), np.array([-3.0, 2.0, 2.0]))
    log_w = ContextFactor(grid).log_weight(before, after, None)
    assert log_w.tolist() == [0.0, FORBIDDEN_LOG_WEIGHT, 0.0]  # the third was there already
    naive = ContextFactor(grid, "naive").log_weight(before, after, None)
    assert naive.tolist() == [0.0, FORBIDDEN_LOG_WEIGHT, FORBIDDEN_LOG_WEIGHT]
    with pytest.raises(ValueError):
        ContextFactor(grid, "often")


def test_configuration_builds_the_factors():
    beacons, floats = synthetic_scenario(days=10, rng=1)
    info = floats[0]
    assert context_factors(load_config(), beacons, info) == ()
    (factor,) = context_factors(load_config(overrides={"context": {"land": True}}), beacons, info)
    lat, lon = np.array([info.launch_lat, -54.8]), np.array([info.launch_lon, -68.3])  # open sea; Tierra del Fuego
    assert factor.grid.cf_at(lon[:1], lat[:1])[0] == pytest.approx(0.999)
    with pytest.raises(InputError, match="needs the float's depth; expected a depth_m column"):
        context_factors(load_config(overrides={"context": {"bathymetry": "x.nc"}}), beacons, info)


def test_a_float_along_a_ridge_with_a_gap():
    """The must-show case (`papers.context.floats_ridge`, small): the smoothed track is
    closer to the truth with the bathymetry constraint, and never where the sea floor is
    shallower than the float."""
    sz = floats_ridge.Sizes(repeats=4, days=66, particles=200)
    runs = [floats_ridge.track_pair((seed, sz)) for seed in range(sz.repeats)]
    rmse = {k: np.mean([np.sqrt(np.mean(r[k]["err_km"] ** 2)) for r in runs]) for k in ("with", "without")}
    # 24.1 vs 25.4 km here (better on 3 of the 4 floats; the full experiment: 8 floats, 90 days)
    assert rmse["with"] < rmse["without"]
    forbidden = floats_ridge.FLOAT_DEPTH_M - floats_ridge.FORBIDDEN_MARGIN_M  # beyond the grid's depth uncertainty
    assert all(np.all(r["with"]["depth_m"] > forbidden) for r in runs)


def test_cli_bathymetry_option_end_to_end(sim_mission_dir, tmp_path):
    mission = tmp_path / "mission"
    shutil.copytree(sim_mission_dir, mission)
    floats_csv = (mission / "floats.csv").read_text().splitlines()
    (mission / "floats.csv").write_text("\n".join([floats_csv[0] + ",depth_m"] + [r + ",1000" for r in floats_csv[1:]]))
    _beacons, floats = synthetic_scenario(days=20, rng=np.random.default_rng(3))
    info = dataclasses.replace(floats[0], launch_lat=-58.0, launch_lon=-90.0)
    grid = floats_ridge.write_ridge_grid(tmp_path / "ridge.nc", info, cell_arcmin=4.0)
    out = tmp_path / "out"
    result = CliRunner().invoke(
        main, ["track", str(mission / "sim1.csv"), "--bathymetry", str(grid), "--out", str(out)]
    )
    assert result.exit_code == 0, result.output
    run = json.loads((out / "sim1" / "run.json").read_text())
    assert run["config"]["context"]["bathymetry"] == str(grid)
    assert (out / "sim1" / "track.png").is_file()
    bad = tmp_path / "bad.nc"
    bad.write_text("no grid here")
    result = CliRunner().invoke(main, ["track", str(mission / "sim1.csv"), "--bathymetry", str(bad), "--out", str(out)])
    assert result.exit_code == 2
    assert result.output.strip().count("\n") == 0 and "bad.nc: cannot read as a NetCDF grid" in result.output
