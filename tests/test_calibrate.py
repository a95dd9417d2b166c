"""calibrate(): the entry point from a first pass's estimate (explicit keys kept, too few
confident arrivals refused), Calibration's lookups, and the per-beacon detection fit."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.special import expit

from rafostrack.calibrate import MIN_ARRIVALS, Calibration, calibrate
from rafostrack.calibrate.detection import MIN_OPPORTUNITIES, fit_detection
from rafostrack.config import load_config, with_overrides
from rafostrack.model.measurement import predicted_toa_s, window_beacons
from rafostrack.problem import FloatProblem, ModelValues
from rafostrack.sim.evaluate import truth_estimate
from rafostrack.sim.scenarios import synthetic_scenario
from rafostrack.sim.simulate import simulate_mission
from rafostrack.summaries.estimates import Estimate

CONFIG = load_config()
C_TRUE = 1486.0


def _calibrate(estimate, record, beacons, info, config=CONFIG, explicit=frozenset()):
    """`calibrate` of the float's problem under `config`, with `explicit` as the keys the user set."""
    problem = FloatProblem(beacons, info, dataclasses.replace(config, explicit=frozenset(explicit)))
    return calibrate(estimate, record, problem)


def _first_pass(days: int, seed: int, **model_changes):
    """A simulated float (sound speed 1486 m/s against the configured 1480) and a
    'first pass' estimate made of its truth: the true track, every stored TOA labelled
    with its true source at probability 1 (clutter: no beacon)."""
    beacons, (info,) = synthetic_scenario(days=days, rng=seed)
    info = dataclasses.replace(info, max_signals=8)
    model = dataclasses.replace(CONFIG.model, sound_speed_m_s=C_TRUE, toa_sigma_s=1.0, clutter_rate=0.5)
    model = dataclasses.replace(model, **model_changes)
    sim = simulate_mission(beacons, [info], model, np.random.default_rng(seed)).floats[0]
    return truth_estimate(sim), sim.record, beacons, sim.info


@pytest.fixture(scope="module")
def first_pass():
    return _first_pass(days=30, seed=4)


@pytest.fixture(scope="module")
def calibrated(first_pass) -> Calibration:
    return _calibrate(*first_pass, CONFIG)


EXPLICIT = {("model", "toa_sigma_s"), ("motion", "decorrelation_days"), ("model", "clutter_rate")}


def _values(calibration: Calibration) -> dict[tuple[str, str], float]:
    return dict(calibration.model.items())


def test_every_calibrated_key_is_estimated_and_applied(first_pass, calibrated):
    """Every model value calibration can set is estimated; the calibrated problem tracks
    with them beside the user's configuration, which is left as it was."""
    assert calibrated is not None
    assert set(_values(calibrated)) == set(ModelValues.keys())
    problem = calibrated.calibrated(FloatProblem(first_pass[2], first_pass[3], CONFIG))
    assert problem.config is CONFIG
    applied = problem.tracking_config
    for (section, key), value in _values(calibrated).items():
        assert getattr(getattr(applied, section), key) == value
    assert abs(calibrated.model.sound_speed_m_s - C_TRUE) < 3.0  # 1480 configured
    assert calibrated.report["kept_as_configured"] == []
    assert calibrated.report["arrivals_used"] == int(first_pass[0].labels["beacon_id"].notna().sum())


def test_explicit_keys_are_kept_not_estimated(first_pass, calibrated):
    """Keys the user set are absent from the estimates, keep the configured values when
    applied and are reported as kept; the other Kalman-fitted keys are as without them."""
    kept = _calibrate(*first_pass, CONFIG, explicit=EXPLICIT)
    assert kept is not None
    assert EXPLICIT.isdisjoint(_values(kept))
    assert set(_values(kept)) == set(ModelValues.keys()) - EXPLICIT
    applied = kept.model.applied(CONFIG)
    for section, key in EXPLICIT:
        assert getattr(getattr(applied, section), key) == getattr(getattr(CONFIG, section), key)
        # ... and the estimate would have differed from the configured value.
        assert _values(calibrated)[(section, key)] != getattr(getattr(CONFIG, section), key)
    assert kept.report["kept_as_configured"] == sorted(f"[{s}] {k}" for s, k in EXPLICIT)
    for key in (("model", "sound_speed_m_s"), ("motion", "velocity_sd_km_per_day"), ("motion", "diffusion_km_per_day")):
        assert _values(kept)[key] == _values(calibrated)[key]


def test_an_explicit_sound_speed_is_the_one_the_calibrated_pass_uses(first_pass):
    estimate, record, beacons, info = first_pass
    kept = _calibrate(estimate, record, beacons, info, CONFIG, explicit={("model", "sound_speed_m_s")})
    config = kept.model.applied(CONFIG)
    assert config.model.sound_speed_m_s == CONFIG.model.sound_speed_m_s
    wb = window_beacons(kept.beacons, kept.info, record.windows[5].time)
    plain = window_beacons(dataclasses.replace(kept.beacons, sound_speed_m_s=None), kept.info, record.windows[5].time)
    ranges = np.full((1, len(wb.index)), 600e3)
    np.testing.assert_allclose(predicted_toa_s(ranges, wb, config.model), predicted_toa_s(ranges, plain, config.model))


def test_the_clock_random_walk_is_not_fitted_below_its_floor(first_pass, calibrated):
    """`[calibrate] min_clock_rate_sd_s_per_day` bounds the fitted clock wander from below:
    a floor above the value fitted without one is where the fit stops."""
    free = with_overrides(CONFIG, calibrate={"min_clock_rate_sd_s_per_day": 0.0})
    q = _calibrate(*first_pass, free).report["clock_rate_sd_s_per_day"]
    floor = 3 * max(q, CONFIG.calibrate.min_clock_rate_sd_s_per_day)
    held = _calibrate(*first_pass, with_overrides(CONFIG, calibrate={"min_clock_rate_sd_s_per_day": floor}))
    assert held.report["clock_rate_sd_s_per_day"] == pytest.approx(floor, abs=1e-5)
    assert calibrated.report["clock_rate_sd_s_per_day"] >= CONFIG.calibrate.min_clock_rate_sd_s_per_day - 1e-5


def _with_confident(estimate: Estimate, n: int) -> Estimate:
    """The estimate with only its first n source labels confident (the others at 0.85)."""
    labels = estimate.labels.copy()
    sourced = np.flatnonzero(labels["beacon_id"].notna().to_numpy())
    labels.loc[labels.index[sourced[n:]], "prob"] = 0.85
    return dataclasses.replace(estimate, labels=labels)


def test_too_few_confident_arrivals_give_none(first_pass):
    estimate, record, beacons, info = first_pass
    assert _calibrate(_with_confident(estimate, MIN_ARRIVALS - 1), record, beacons, info, CONFIG) is None
    enough = _calibrate(_with_confident(estimate, MIN_ARRIVALS), record, beacons, info, CONFIG)
    assert enough is not None and enough.report["arrivals_used"] == MIN_ARRIVALS
    # Labels in ambiguous windows do not count, however sure.
    ambiguous = estimate.track.copy()
    ambiguous["ambiguous"] = True
    assert _calibrate(dataclasses.replace(estimate, track=ambiguous), record, beacons, info, CONFIG) is None
    # Confident clutter labels (no beacon) do not count either.
    clutter = estimate.labels.assign(beacon_id=None, prob=1.0)
    assert _calibrate(dataclasses.replace(estimate, labels=clutter), record, beacons, info, CONFIG) is None


@pytest.mark.xfail(
    strict=True,
    reason="known defect: kalman.fit's 4 Gauss-Newton/EM iterations start with every arrival at weight 1, so "
    "with 10% multipath the TOA noise sd is still shrinking when they stop (~1.26 s for a true 1.0 s)",
)
def test_toa_sigma_is_recovered_with_multipath_arrivals():
    estimate, record, beacons, info = _first_pass(days=60, seed=0, multipath_fraction=0.1, echo_fraction=0.0)
    fitted = _calibrate(estimate, record, beacons, info, CONFIG)
    assert abs(fitted.values[("model", "toa_sigma_s")] - 1.0) < 0.1


def test_nuisance_cov_at_takes_the_nearest_node():
    t0 = np.datetime64("2010-01-01T00:00", "ns")
    nodes = t0 + np.array([0, 10, 11, 30], dtype="timedelta64[h]").astype("timedelta64[ns]")
    cov = np.arange(4)[:, None, None] * np.eye(2)[None] + 1.0
    cal = Calibration({}, None, None, nuisance_time=nodes, nuisance_cov_km2=cov)  # type: ignore[arg-type]
    hours = np.array([-5, 0, 4, 5, 6, 10, 10.4, 10.6, 20, 20.5, 21, 30, 99])
    times = t0 + (hours * 3600e9).astype("timedelta64[ns]")
    got = cal.nuisance_cov_at(times)
    gaps = np.abs(times.astype(np.int64)[:, None] - nodes.astype(np.int64)[None, :])
    nearest = np.argmin(gaps, axis=1)  # ties: the earlier node
    np.testing.assert_array_equal(got, cov[nearest])
    single = Calibration({}, None, None, nuisance_time=nodes[:1], nuisance_cov_km2=cov[:1])  # type: ignore[arg-type]
    np.testing.assert_array_equal(single.nuisance_cov_at(times), np.repeat(cov[:1], len(times), axis=0))
    assert Calibration({}, None, None).nuisance_cov_at(times).shape == (len(times), 2, 2)  # type: ignore[arg-type]


@pytest.mark.parametrize(("p", "r50"), [(0.85, 900.0), (0.6, 500.0)])
def test_fit_detection_is_the_maximum_likelihood_and_recovers_the_truth(p, r50):
    """Bernoulli outcomes drawn from p / (1 + exp((range - R) / w)): on 600 draws the fit
    is the likelihood's maximum found by brute force on a grid (the oracle: the sample's
    MLE, not the truth); on 4000 draws it is close to the truth."""
    rng = np.random.default_rng(21)
    falloff = 100.0

    def draw(n: int) -> tuple[np.ndarray, np.ndarray]:
        ranges = rng.uniform(100.0, 1600.0, n)
        return ranges, (rng.random(n) < p * expit(-(ranges - r50) / falloff)).astype(float)

    ranges, heard = draw(600)

    def nll(pp: np.ndarray, rr: np.ndarray) -> np.ndarray:
        prob = np.clip(pp[..., None] * expit(-(ranges - rr[..., None]) / falloff), 1e-12, 1 - 1e-12)
        return -np.sum(heard * np.log(prob) + (1 - heard) * np.log1p(-prob), axis=-1)

    # A coarse grid over the whole box, then a fine one about its best point.
    grid_p, grid_r = np.meshgrid(np.linspace(0.05, 0.995, 64), np.linspace(50.0, 2000.0, 131), indexing="ij")
    values = nll(grid_p, grid_r)
    at = np.unravel_index(np.argmin(values), values.shape)
    fine_p = np.clip(np.linspace(grid_p[at] - 0.03, grid_p[at] + 0.03, 61), 0.05, 0.995)
    fine_r = np.linspace(grid_r[at] - 30.0, grid_r[at] + 30.0, 61)
    grid_p, grid_r = np.meshgrid(fine_p, fine_r, indexing="ij")
    values = nll(grid_p, grid_r)
    best = np.unravel_index(np.argmin(values), values.shape)
    got_p, got_r = fit_detection(ranges, heard, falloff, 0.9, 0.0)
    assert nll(np.array(got_p), np.array(got_r)) <= values[best] + 1e-6  # at least as good as the grid's best
    assert abs(got_p - grid_p[best]) < 0.01 and abs(got_r - grid_r[best]) < 10.0
    ranges, heard = draw(4000)
    got_p, got_r = fit_detection(ranges, heard, falloff, 0.5, 1500.0)
    assert abs(got_p - p) < 0.05
    assert abs(got_r - r50) < 40.0
    few = MIN_OPPORTUNITIES - 1
    assert fit_detection(ranges[:few], heard[:few], falloff, 0.9, 0.0) is None
    assert fit_detection(ranges[: few + 1], heard[: few + 1], falloff, 0.9, 0.0) is not None


def test_the_report_gives_the_detection_of_every_beacon_fitted_heard_or_not(first_pass):
    """A beacon whose arrivals the first pass all called clutter is not in the timing fit
    (no offset correction reported) but has a detection fit; run.json reports it, as the
    calibrated beacon table has it, with its opportunities, and lists it as heard nowhere
    (its fit at p's lower bound); the other beacons are heard. With detection set by the
    user, no fit is used and none is reported."""
    estimate, record, beacons, info = first_pass
    silenced = estimate.labels["beacon_id"].value_counts().index[0]  # the most heard: many opportunities
    labels = estimate.labels.assign(
        beacon_id=estimate.labels["beacon_id"].where(estimate.labels["beacon_id"] != silenced)
    )
    fitted = _calibrate(dataclasses.replace(estimate, labels=labels), record, beacons, info, CONFIG)
    assert fitted is not None
    report = fitted.report["beacons"]
    assert "offset_correction_s" not in report[silenced] and "p_detect" in report[silenced]
    ids = list(fitted.beacons.beacon_id)
    detected = [name for name in ids if np.isfinite(fitted.beacons.p_detect[ids.index(name)])]
    assert silenced in detected and sorted(name for name in report if "p_detect" in report[name]) == sorted(detected)
    for name in detected:
        row = ids.index(name)
        assert report[name]["p_detect"] == round(float(fitted.beacons.p_detect[row]), 3)
        assert report[name]["detection_range_km"] == round(float(fitted.beacons.detection_range_km[row]), 1)
    assert report[silenced]["detection_heard"] == 0
    assert report[silenced]["detection_opportunities"] >= MIN_OPPORTUNITIES
    assert fitted.report["sources_heard_nowhere"] == [silenced]
    assert all(report[name]["detection_heard"] > 0 for name in detected if name != silenced)
    explicit = {("model", "p_detect")}
    kept = _calibrate(dataclasses.replace(estimate, labels=labels), record, beacons, info, CONFIG, explicit=explicit)
    assert kept is not None and kept.beacons.p_detect is None
    assert kept.report["sources_heard_nowhere"] == []
    assert not any("p_detect" in entry for entry in kept.report["beacons"].values())
