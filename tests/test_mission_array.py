"""The mission's array fit: the block-arrow solve against a dense least-squares solve, and
a simulated mission whose table carries several faults at once."""

from __future__ import annotations

import csv
import dataclasses
import warnings

import numpy as np
import pytest
from scipy import sparse

from rafostrack.batch.pool import ordered_map
from rafostrack.calibrate import kalman
from rafostrack.calibrate.kalman_problem import NODE
from rafostrack.calibrate.metadata_checks import CONSISTENT, CONTRADICTED, UNDETERMINED
from rafostrack.calibrate.value_check import z_of
from rafostrack.config import load_config
from rafostrack.mission.array import calibrated_array, released_in
from rafostrack.mission.array_checks import array_values
from rafostrack.mission.array_fit import ArrayLayout, ArrayPriors
from rafostrack.mission.floats import BANDWIDTH, mission_float, referred
from rafostrack.mission.outputs import ARRAY_NAME, CALIBRATED_NAME, array_rows, write_array_outputs
from rafostrack.mission.schur import OUTLIER_ALPHA, FloatBlock, outlying, outlying_together, solve_mission
from rafostrack.model.geodesy import displace
from rafostrack.sim.evaluate import truth_estimate
from rafostrack.sim.scenarios import synthetic_scenario
from rafostrack.sim.simulate import simulate_mission

CONFIG = load_config()
N_BEACONS = 8


def _mission(n_floats: int, days: int, seed: int = 5):
    beacons, infos = synthetic_scenario(n_beacons=N_BEACONS, days=days, rng=seed, n_floats=n_floats)
    beacons = dataclasses.replace(beacons, source_file="beacons.csv", source_line=np.arange(2, N_BEACONS + 2))
    infos = [dataclasses.replace(i, max_signals=8) for i in infos]
    model = dataclasses.replace(CONFIG.model, toa_sigma_s=1.0, clutter_rate=0.5)
    return beacons, simulate_mission(beacons, infos, model, np.random.default_rng(seed + 6)).floats


def _floats(beacons, simulated):
    built = [mission_float(s.info.float_id, truth_estimate(s), beacons, s.info, CONFIG) for s in simulated]
    assert all(f is not None for f in built)
    return built


def _dense_rows(lin, hyper, columns, n_total, offset):
    """A float's whitened rows as a dense Jacobian over the mission's unknowns (its own at
    `offset`, its array columns at theta's place after every float's own)."""
    jac_a, r_a = lin.arrival_system
    jac_f, r_f = lin.motion_rows(hyper).system(lin.problem.n_unknowns)
    fixed_jac = sparse.vstack([jac_a / hyper.toa_sigma_s, jac_f])
    rows = sparse.csr_matrix(fixed_jac).toarray()
    resid = np.concatenate([r_a / hyper.toa_sigma_s, r_f])
    n_own = rows.shape[1] - len(columns)
    out = np.zeros((rows.shape[0], n_total))
    out[:, offset : offset + n_own] = rows[:, :n_own]
    out[:, columns] += rows[:, n_own:]
    return out, resid


@pytest.fixture(scope="module")
def three_floats():
    """Three floats' blocks of the mission system at a random point, with the same rows as
    dense matrices (`_dense_rows`) and the array's prior."""
    beacons, simulated = _mission(3, 20)
    floats = _floats(beacons, simulated)
    layout = ArrayLayout.of(floats)
    floats = referred(floats, layout.sources, layout.mid_days)
    rng = np.random.default_rng(1)
    theta = rng.normal(0.0, 0.3, layout.size) * np.r_[1e-7, np.tile([1.0, 1e-3, 1e-7, 1.0, 1.0], len(layout.sources))]
    prior_sd = ArrayPriors.of(layout, kalman.DEFAULT_PRIORS, 1 / 1480.0).sd()
    n_own_total = sum(f.n_own for f in floats)
    n_total = n_own_total + layout.size
    blocks, dense, offset = [], [], 0
    for f in floats:
        columns = layout.float_columns(f)
        u = np.concatenate([rng.normal(0.0, 0.5, f.n_own), theta[columns]])
        lin = kalman.linearise(f.problem, u, np.ones(f.n_arrivals), kalman.DEFAULT_PRIORS, array_priors=False)
        normal = lin.normal(f.hyper)
        blocks.append(FloatBlock.of(normal.jtj, -normal.jtr, NODE * f.problem.n_nodes, BANDWIDTH, f.n_own, columns))
        rows, r = _dense_rows(lin, f.hyper, n_own_total + columns, n_total, offset)
        fixed = sparse.csr_matrix(lin.fixed.jtj).toarray()  # end fix and the mean current's prior, as normal terms
        dense.append((rows, r, fixed, lin.fixed.jtr, offset, columns, f.n_own))
        offset += f.n_own
    return blocks, dense, theta, prior_sd, n_own_total


def _dense_solve(dense, theta, prior_sd, n_own_total, left_out=None):
    """The dense Gauss-Newton step of the mission, N = J'J + the fixed terms + the prior, all
    placed in the mission's unknowns; float `left_out`'s rows and own unknowns dropped.
    Returns its own unknowns' step (every float's, in order; zeros for the one left out),
    the array's step and N^-1 on the array's columns."""
    n_total = n_own_total + len(theta)
    normal, rhs = np.zeros((n_total, n_total)), np.zeros(n_total)
    kept = np.ones(n_total, dtype=bool)
    for k, (rows, r, fixed, fixed_jtr, at, columns, n_own) in enumerate(dense):
        if k == left_out:
            kept[at : at + n_own] = False
            continue
        normal += rows.T @ rows
        rhs -= rows.T @ r
        place = np.r_[at : at + fixed.shape[0] - len(columns), n_own_total + columns]
        normal[np.ix_(place, place)] += fixed
        rhs[place] -= fixed_jtr
    array = np.arange(n_own_total, n_total)
    normal[array, array] += prior_sd**-2.0
    rhs[array] -= prior_sd**-2.0 * theta
    step = np.zeros(n_total)
    step[kept] = np.linalg.solve(normal[np.ix_(kept, kept)], rhs[kept])
    covariance = np.linalg.inv(normal[np.ix_(kept, kept)])[-len(theta) :, -len(theta) :]
    return step[:n_own_total], step[array], covariance


def test_block_arrow_solve_equals_a_dense_least_squares_solve(three_floats):
    """Three floats' rows stacked into one dense Jacobian with the array's prior rows: the
    least-squares step equals the Schur-complement solve's, for theta and every float."""
    blocks, dense, theta, prior_sd, n_own_total = three_floats
    solution = solve_mission(blocks, np.diag(prior_sd**-2.0), -(prior_sd**-2.0) * theta)
    own_step, array_step, covariance = _dense_solve(dense, theta, prior_sd, n_own_total)
    np.testing.assert_allclose(solution.d_theta, array_step, rtol=1e-6, atol=1e-9 * np.abs(array_step).max())
    own = np.concatenate(solution.d_own)
    np.testing.assert_allclose(own, own_step, rtol=1e-6, atol=1e-8 * np.abs(own_step).max())
    np.testing.assert_allclose(solution.covariance(), covariance, rtol=1e-6, atol=1e-14)


def test_each_float_left_out_equals_a_dense_solve_without_it(three_floats):
    """The jackknife's steps: with float f's rows and unknowns dropped from the dense
    system, its array step equals `left_out_steps()[f]`; the jackknife covariance is the
    spread of those steps by its formula."""
    blocks, dense, theta, prior_sd, n_own_total = three_floats
    solution = solve_mission(blocks, np.diag(prior_sd**-2.0), -(prior_sd**-2.0) * theta)
    steps = solution.left_out_steps()
    for k in range(len(dense)):
        _, array_step, _ = _dense_solve(dense, theta, prior_sd, n_own_total, left_out=k)
        np.testing.assert_allclose(steps[k], array_step, rtol=1e-6, atol=1e-9 * np.abs(array_step).max())
    assert not np.allclose(steps[0], steps[1])  # the floats differ: the spread is not nothing
    centred = steps - steps.mean(axis=0)
    np.testing.assert_allclose(solution.jackknife_covariance(), (2 / 3) * centred.T @ centred)


def test_an_outlying_float_is_found_at_its_rate_and_a_far_one_always():
    """`outlying` against a Monte Carlo oracle: m equal Gaussian floats give an outlier on
    about `OUTLIER_ALPHA` of draws; one float shifted by 10 sd is found on nearly all draws
    where 8 floats or more tell (4 hardly can: F(1, 2)'s tail is long); never below 4."""
    rng = np.random.default_rng(3)
    for m, power in ((4, 0.1), (8, 0.95), (24, 0.999)):
        steps = rng.standard_normal((20_000, m))
        shifted = steps + 10.0 * (np.arange(m) == 0)
        for draws, low, high in ((steps, OUTLIER_ALPHA - 0.003, OUTLIER_ALPHA + 0.003), (shifted, power, 1.0)):
            farthest, found = outlying(draws.T, np.full(len(draws), m))  # a column a draw
            assert low <= found.mean() <= high
        assert np.all(farthest[found] == 0)  # the shifted float, where one is found
    assert not outlying(np.array([[0.0], [0.1], [1e9]]), np.array([3]))[1].any()  # too few to tell
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # one float: no others to average, and nothing said
        assert not outlying(np.array([[1e9, 0.0]]), np.array([1, 1]))[1].any()


def test_outliers_tested_together_are_found_at_the_rate_of_one_test():
    """`outlying_together` against a Monte Carlo oracle: 32 unknowns of 10 equal Gaussian
    floats each (and 8 of 3 floats, which are not tested) give an outlier in any of them on
    at most `OUTLIER_ALPHA` of draws (Bonferroni: about that, the unknowns independent); a
    float shifted by 12 sd in one unknown among 24 floats is still found on nearly every draw."""
    rng = np.random.default_rng(5)
    touching = np.array([10] * 32 + [3] * 8)
    any_found, shifted_found = [], []
    for _ in range(4000):
        steps = rng.standard_normal((10, 40))
        any_found.append(outlying_together(steps, touching)[1].any())
        wide = rng.standard_normal((24, 32))
        wide[0, 0] += 12.0
        farthest, found = outlying_together(wide, np.full(32, 24))
        shifted_found.append(found[0] and farthest[0] == 0)
    assert OUTLIER_ALPHA - 0.004 <= np.mean(any_found) <= OUTLIER_ALPHA + 0.004
    assert np.mean(shifted_found) > 0.99


@pytest.fixture(scope="module")
def mission():
    return _mission(8, 90)


@pytest.fixture(scope="module")
def faulted_array(mission):
    """The mission's array calibrated with three values wrong (`_faulted`), and that table."""
    beacons, simulated = mission
    faulted = _faulted(beacons)
    return calibrated_array(_floats(faulted, simulated), faulted, CONFIG), faulted


def _faulted(beacons):
    """Three values wrong at once: an offset +25 s, a drift +0.035 s/day, a position 18 km east."""
    offset = beacons.offset_s + np.eye(N_BEACONS)[1] * 25.0
    drift = beacons.drift_s_per_day + np.eye(N_BEACONS)[4] * 0.035
    lat, lon = displace(beacons.lat[6], beacons.lon[6], 18.0, 0.0)
    at = np.arange(N_BEACONS) == 6
    return dataclasses.replace(
        beacons,
        offset_s=offset,
        drift_s_per_day=drift,
        lat=np.where(at, lat, beacons.lat),
        lon=np.where(at, lon, beacons.lon),
    )


def _clock_at_mid(table, array, row: int) -> float:
    """A table's clock of the source in `row` at the mission's mean time of its arrivals."""
    g = int(np.searchsorted(array.fit.layout.sources, row))
    return float(table.offset_s[row] + table.drift_s_per_day[row] * array.fit.layout.mid_days[g])


def test_a_mission_names_several_faults_at_once_and_recovers_them_within_two_sd(mission, faulted_array):
    beacons, _ = mission
    array, faulted = faulted_array
    by_value = {(v.check.id, v.check.field): v.check for v in array.values}
    wrong = {("B2", "offset_s"), ("B2", "clock_s"), ("B5", "drift_s_per_day"), ("B7", "position")}
    assert {key for key, c in by_value.items() if c.outcome == CONTRADICTED} == wrong
    assert {(v.check.id, v.check.field) for v in array.decided()} == wrong
    # A wrong value makes the floats that see it best differ the most: none is set aside on
    # it before its release (sim7's B5 arrivals were, when every source was tested).
    assert not [pair for pair in array.set_aside() if pair.split()[1] in {"B2", "B5", "B7"}]
    offset, drift = by_value["B2", "offset_s"], by_value["B5", "drift_s_per_day"]
    assert abs(offset.supported - beacons.offset_s[1]) < 2 * offset.sd
    assert abs(drift.supported - beacons.drift_s_per_day[4]) < 2 * drift.sd
    position = by_value["B7", "position"]
    north, east = (np.array(position.supported_lat_lon) - (beacons.lat[6], beacons.lon[6])) * (
        111.0,
        111.0 * np.cos(np.radians(beacons.lat[6])),
    )
    assert np.hypot(north, east) < 2 * position.sd
    table = array.calibrated_beacons()
    untouched = [0, 2, 3, 5, 6, 7]
    np.testing.assert_array_equal(table.offset_s[untouched], faulted.offset_s[untouched])
    assert table.drift_s_per_day[4] == drift.supported
    # The offsets written put each clock over the mission at the arrivals' value.
    clock = by_value["B2", "clock_s"]
    assert _clock_at_mid(table, array, 1) == pytest.approx(clock.supported, abs=1e-9)
    assert abs(clock.supported - _clock_at_mid(beacons, array, 1)) < 2 * clock.sd
    assert _clock_at_mid(table, array, 4) == pytest.approx(by_value["B5", "clock_s"].supported, abs=1e-9)


def test_where_the_mission_cannot_split_a_clock_error_it_puts_the_clock_right(mission):
    """The sources' start (their clocks' epoch) 700 days before a 90-day mission: a drift
    0.01 s/day off (B2: its clock 7 s off, the drift not decidable), the same with an offset
    20 s off (B4), an offset 20 s off alone (B6). Each clock over the mission is contradicted
    and no drift is; the table written keeps the drifts and puts each clock within 2 sd of
    the truth's (the true drifts are 0: the simulated floats are the same)."""
    beacons, simulated = mission
    start = min(s.info.launch_time for s in simulated) - np.timedelta64(700, "D")
    true = dataclasses.replace(beacons, start=np.full(N_BEACONS, start))
    wrong_drift, wrong_offset = np.eye(N_BEACONS)[[1, 3]].sum(0), np.eye(N_BEACONS)[[3, 5]].sum(0)
    faulted = dataclasses.replace(
        true, drift_s_per_day=true.drift_s_per_day + 0.01 * wrong_drift, offset_s=true.offset_s + 20.0 * wrong_offset
    )
    array = calibrated_array(_floats(faulted, simulated), faulted, CONFIG)
    contradicted = {(v.check.id, v.check.field) for v in array.values if v.check.outcome == CONTRADICTED}
    assert contradicted - {("B4", "offset_s"), ("B6", "offset_s")} == {
        ("B2", "clock_s"),
        ("B4", "clock_s"),
        ("B6", "clock_s"),
    }
    table = array.calibrated_beacons()
    np.testing.assert_array_equal(table.drift_s_per_day, faulted.drift_s_per_day)
    clocks = {v.check.id: v.check for v in array.values if v.check.field == "clock_s"}
    for row in (1, 3, 5):
        clock = clocks[f"B{row + 1}"]
        assert _clock_at_mid(table, array, row) == pytest.approx(clock.supported, abs=1e-9)
        assert abs(clock.supported - _clock_at_mid(true, array, row)) < 2 * clock.sd
    assert np.flatnonzero(table.offset_s != faulted.offset_s).tolist() == [1, 3, 5]
    rows = {(r["source"], r["field"]): r for r in array_rows(array)}
    assert rows["B2", "offset_s"]["outcome"] != CONTRADICTED
    assert rows["B2", "offset_s"]["calibrated"] == f"{table.offset_s[1]:.3f}"
    mid = np.timedelta64(round(float(array.fit.layout.mid_days[1]) * 1440), "m")
    assert rows["B2", "clock_s"]["at"] == str((start + mid).astype("datetime64[m]"))


def test_the_mission_judges_its_values_at_its_own_z_score(faulted_array):
    """`[checks] mission_z_score` sets where a mission's value is contradicted, a float's
    `z_score` does not, but for the sources' clocks: with the mission's just beyond a fault's
    z, that fault is undetermined; with a float's beyond a clock's, the clock is."""
    array, faulted = faulted_array
    fit = array.fit

    def judged(checks):
        return {(v.check.id, v.check.field): v.check for v in array_values(fit, faulted, checks)}

    drift = judged(CONFIG.checks)["B5", "drift_s_per_day"]
    assert drift.outcome == CONTRADICTED
    clock = judged(CONFIG.checks)["B2", "clock_s"]
    assert clock.outcome == CONTRADICTED
    stricter_float = judged(dataclasses.replace(CONFIG.checks, z_score=1.05 * z_of(clock)))
    assert stricter_float["B2", "clock_s"].outcome != CONTRADICTED
    del stricter_float["B2", "clock_s"]
    assert stricter_float.items() <= judged(CONFIG.checks).items()
    stricter = dataclasses.replace(CONFIG.checks, mission_z_score=1.05 * z_of(drift))
    assert judged(stricter)["B5", "drift_s_per_day"].outcome == UNDETERMINED
    assert judged(stricter)["B2", "clock_s"] == clock


def test_the_values_the_floats_were_tracked_with_start_released(mission, faulted_array, tmp_path):
    """A later round: the floats tracked with the calibrated table (here, the truth's labels
    and tracks with its decided values). Those values start released and are decided again
    within 2 sd of the truth; the table as given releases nothing. Written with that table
    kept, array.csv's `calibrated` names what the kept table holds, and a kept table stays
    even when this round decides nothing."""
    beacons, simulated = mission
    first, faulted = faulted_array
    table = first.calibrated_beacons()
    layout = first.fit.layout
    assert not released_in(layout, faulted, faulted).any()
    released = released_in(layout, faulted, table)
    # B5's offset moved with its drift, its clock over the mission kept at the arrivals'.
    assert {(int(layout.sources[g]), b) for g, b in zip(*np.nonzero(released), strict=True)} == {
        (1, 0), (4, 0), (4, 1), (6, 3), (6, 4)
    }  # fmt: skip
    later = calibrated_array(_floats(faulted, simulated), faulted, CONFIG, tracked_with=table)
    assert {(v.check.id, v.check.field) for v in later.decided()} == {
        ("B2", "offset_s"), ("B2", "clock_s"), ("B5", "drift_s_per_day"), ("B7", "position")
    }  # fmt: skip
    offset = next(v.check for v in later.values if (v.check.id, v.check.field) == ("B2", "offset_s"))
    assert abs(offset.supported - beacons.offset_s[1]) < 2 * offset.sd

    given = tmp_path / "beacons.csv"
    given.write_text("beacon_id,lat,lon,offset_s\n" + "".join(f"B{k + 1},0,0,0\n" for k in range(N_BEACONS)))
    (tmp_path / CALIBRATED_NAME).write_text("kept\n")
    nothing = dataclasses.replace(later, released=np.zeros_like(later.released))  # decides nothing
    assert nothing.decided() == []
    write_array_outputs(nothing, tmp_path, given, plots=False, kept=table)
    assert (tmp_path / CALIBRATED_NAME).read_text() == "kept\n"
    rows = list(csv.DictReader((tmp_path / ARRAY_NAME).open()))
    assert {(r["source"], r["field"]): r["calibrated"] for r in rows if r["calibrated"]} == {
        ("B2", "offset_s"): f"{table.offset_s[1]:.3f}",
        ("B5", "offset_s"): f"{table.offset_s[4]:.3f}",
        ("B5", "drift_s_per_day"): f"{table.drift_s_per_day[4]:.5f}",
        ("B7", "position"): f"{table.lat[6]:.4f} {table.lon[6]:.4f}",
    }
    write_array_outputs(nothing, tmp_path, given, plots=False)
    assert not (tmp_path / CALIBRATED_NAME).exists()


def test_a_table_within_one_sd_of_every_decided_value_holds_the_decisions(faulted_array):
    """The mission is settled in a table whose decided values lie within one sd of the
    mission's (B2's clock moved 0.9 sd: settled, 1.1 sd: not), and not in one where a value
    the mission did not decide differs from the table as given, however little."""
    array, _ = faulted_array
    table = array.calibrated_beacons()
    assert array.moved_sd(table) == 0.0
    assert array.settled_in(table)
    clock_sd = next(v.check.sd for v in array.values if (v.check.id, v.check.field) == ("B2", "clock_s"))

    def offset_moved(row: int, by_s: float):
        return dataclasses.replace(table, offset_s=table.offset_s + by_s * np.eye(N_BEACONS)[row])

    assert array.moved_sd(offset_moved(1, 0.9 * clock_sd)) == pytest.approx(0.9, rel=1e-6)
    assert array.settled_in(offset_moved(1, 0.9 * clock_sd))
    assert array.moved_sd(offset_moved(1, -1.1 * clock_sd)) == pytest.approx(1.1, rel=1e-6)
    assert not array.settled_in(offset_moved(1, -1.1 * clock_sd))
    assert array.moved_sd(offset_moved(0, 1e-3)) == np.inf  # B1: nothing decided
    assert not array.settled_in(offset_moved(0, 1e-3))


def test_a_mission_with_correct_tables_finds_nothing(mission):
    beacons, simulated = mission
    array = calibrated_array(_floats(beacons, simulated), beacons, CONFIG)
    assert {v.check.outcome for v in array.values} == {CONSISTENT}
    assert not array.released.any()
    assert array.decided() == []


@pytest.mark.parametrize("shift_s", [-10.0, -40.0])
def test_one_float_off_on_a_source_is_set_aside_and_the_fault_still_named(mission, shift_s):
    """B2's offset 25 s off (`_faulted`), and one float's arrivals of B2 shifted further
    (early: not multipath; as a float whose track or labels are off gives): its pull on B2
    stands out among B2's floats, its B2 arrivals are set aside, and B2's offset is named
    within 2 sd of the truth, as without the shift. (Without the setting aside it was
    undetermined at 586-618 s, sd 30-57 s: that float alone set B2's spread.)"""
    beacons, simulated = mission
    faulted = _faulted(beacons)
    floats = _floats(faulted, simulated)
    off = simulated[1]
    labels = truth_estimate(off).labels.copy()
    labels.loc[labels["beacon_id"] == "B2", "toa_s"] += shift_s
    floats[1] = mission_float(off.info.float_id, dataclasses.replace(truth_estimate(off), labels=labels),
                              faulted, off.info, CONFIG)  # fmt: skip
    array = calibrated_array(floats, faulted, CONFIG)
    assert f"{off.info.float_id} B2" in array.set_aside()
    decided = next(v for v in array.decided() if (v.check.id, v.check.field) == ("B2", "offset_s"))
    offset = decided.check
    assert abs(offset.supported - beacons.offset_s[1]) < 2 * offset.sd
    # array.csv's `floats`: those whose arrivals of B2 weigh in, those set aside not among them.
    aside = sum(pair.endswith(" B2") for pair in array.set_aside())
    assert decided.floats == sum(1 in f.heard for f in array.fit.floats) - aside


def _with_path_biases(estimate, sd_s: float, rng: np.random.Generator):
    """The estimate's arrivals each delayed by a bias of its (float, source) pair, N(0, sd_s):
    an error the array fit's model lacks (each pair's own sound path, the same on every one
    of its arrivals), so that a float's arrivals are not independent."""
    labels = estimate.labels.copy()
    sources = sorted(labels["beacon_id"].dropna().unique())
    bias = dict(zip(sources, rng.normal(0.0, sd_s, len(sources)), strict=True))
    labels["toa_s"] = labels["toa_s"] + labels["beacon_id"].map(bias).fillna(0.0)
    return dataclasses.replace(estimate, labels=labels)


def test_the_floats_spread_keeps_correlated_errors_from_being_named(mission):
    """Correct tables, every float's arrivals biased per source (`_with_path_biases`, 5 s):
    judged by the arrivals' noise alone, some correct value is contradicted; judged by the
    floats' jackknife spread, none is."""
    beacons, simulated = mission
    rng = np.random.default_rng(11)
    floats = []
    for s in simulated:
        built = mission_float(s.info.float_id, _with_path_biases(truth_estimate(s), 5.0, rng), beacons, s.info, CONFIG)
        assert built is not None
        floats.append(built)
    array = calibrated_array(floats, beacons, CONFIG)
    noise_only = array_values(array.fit, beacons, CONFIG.checks, widen=False)
    assert any(v.check.outcome == CONTRADICTED for v in noise_only)
    assert all(v.check.outcome != CONTRADICTED for v in array.values)
    assert array.decided() == []


@pytest.mark.slow
def test_the_fit_over_worker_processes_gives_the_same_bits(mission, faulted_array):
    """The fit's per-float work mapped over two worker processes (as `rafostrack batch` runs
    it, `pool.ordered_map`) gives the same array, covariance, spread and values as here."""
    _, simulated = mission
    here, faulted = faulted_array
    with ordered_map(2) as map_floats:
        there = calibrated_array(_floats(faulted, simulated), faulted, CONFIG, map_floats)
    for field in ("theta", "covariance", "jackknife"):
        np.testing.assert_array_equal(getattr(there.fit, field), getattr(here.fit, field))
    assert there.values == here.values
    np.testing.assert_array_equal(there.released, here.released)
