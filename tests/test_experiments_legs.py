"""The random-walk leg paper's experiments at tiny size: every script runs, writes its files and
sane numbers; the target simulator and its noise; the Table 2 statistics."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from papers.legs import fig6_interval, fig8_iterations, report, table2_overall
from papers.legs.methods import run_methods, ss_error
from papers.legs.target import NOISE_TYPES, Scenario, make_run, measurement_noise, simulate_target


@pytest.mark.parametrize("kind", NOISE_TYPES)
def test_noise_types_are_centred_with_the_given_variance(kind):
    noise = measurement_noise(kind, 25.0, 40000, np.random.default_rng(1))
    assert np.abs(noise.mean(axis=0)).max() < 0.1
    np.testing.assert_allclose(noise.var(axis=0), 25.0, rtol=0.05)


def test_target_drives_legs_at_the_speeds_and_turns_described():
    t, xy = simulate_target(400.0, np.random.default_rng(2))
    speed = np.hypot(*np.diff(xy, axis=0).T) / np.diff(t)
    assert 7.9 <= speed.min() and speed.max() <= 17.1
    heading = np.unwrap(np.arctan2(*np.diff(xy, axis=0).T[::-1]))
    assert np.abs(np.diff(heading)).max() <= 0.6 * 0.05 + 1e-9  # finite turn rate


def test_methods_on_one_run_and_the_error_measure():
    run = make_run(Scenario(total_s=60.0, sigma2=4.0), np.random.default_rng(3))
    assert ss_error(run.truth_at(run.eval_t), run) == 0.0
    rows = run_methods(run, 600, [1, 2], ("rw_paper", "rw_paper_var", "rw_ours", "rw_student", "kf", "ks"))
    per = {r["method"]: r["ss_per_time"] for r in rows}
    assert all(math.isfinite(v) for v in per.values())
    assert per["rw_ours"] < 5.0 and per["ks"] < 5.0  # measurement sd is 2 units
    again = run_methods(run, 600, [1, 2], ("rw_ours",))
    assert again[0]["ss"] == next(r["ss"] for r in rows if r["method"] == "rw_ours")


def test_wilson_interval():
    lo, hi = table2_overall.wilson(152, 200)
    assert lo == pytest.approx(0.696, abs=0.002) and hi == pytest.approx(0.814, abs=0.002)


def test_experiments_write_files_and_report(tmp_path):
    summaries = {
        "fig6_interval": fig6_interval.run(tmp_path, sizes={"repeats": 1, "iterations": 200}, workers=1),
        "fig8_iterations": fig8_iterations.run(tmp_path, sizes={"repeats": 1, "iterations": (100, 200)}, workers=1),
        "table2_overall": table2_overall.run(tmp_path, sizes={"scenarios": 3, "iterations": 200}, workers=1),
    }
    for summary in summaries.values():
        for name in summary["files"]:
            assert (tmp_path / name).stat().st_size > 0
        assert json.loads((tmp_path / f"{summary['name']}.json").read_text())["name"] == summary["name"]
    assert len(summaries["fig6_interval"]["table"]) == len(fig6_interval.LEVELS)
    pair = summaries["table2_overall"]["pairs"][0]
    assert pair["n"] == 3 and 0 <= pair["a_win_rate"] <= 1
    path = report.build_report(tmp_path)
    text = path.read_text()
    assert "Table 2" in text and "2362.4" in text and "Fig. 8" in text
