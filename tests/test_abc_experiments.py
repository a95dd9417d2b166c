"""The ABC paper's experiments at tiny size (papers.abc): every script runs,
writes its files and sane numbers, is deterministic, and the report builds from them."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from papers.abc import fig2_single, fig3_5_trajectories, report, table1_rmse
from papers.abc.setting import PAPER_TABLE1, CellTask, run_task
from papers.runner import PAPERS, paper_main


@pytest.fixture(scope="module")
def outdir(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("abc_figures")


def check_files(outdir: Path, summary: dict) -> None:
    for name in summary["files"]:
        path = outdir / name
        assert path.is_file() and path.stat().st_size > 0, name
    saved = json.loads((outdir / f"{summary['name']}.json").read_text())
    assert saved["files"] == summary["files"]


def test_registered_and_paper_table_complete():
    assert "abc" in PAPERS
    assert len(PAPER_TABLE1) == 9 and all(set(v) == {16, 64} for v in PAPER_TABLE1.values())


def test_run_task_is_paired_across_algorithms():
    a = run_task(CellTask(16, 2, "rej", 3, 30, 5))
    b = run_task(CellTask(16, 2, "rw", 3, 30, 5))
    assert a["rmse"].shape == (3, 31) and (a["rmse"][:, 0] == b["rmse"][:, 0]).all()  # same starts
    assert 0 <= a["acceptance"] <= 1 and a["simulations_per_step"] == 30


def test_fig2(outdir):
    summary = fig2_single.run(outdir, seed=1, workers=1, sizes={"scenarios": 4, "particles": 40})
    check_files(outdir, summary)
    for alg in ("mcmc", "pt", "rw", "rej"):
        a = summary["algorithms"][alg]
        assert 0 < a["rmse_t10"] < 40 and a["se_t10"] >= 0 and 0 <= a["acceptance"] <= 1
    assert summary["algorithms"]["pt"]["simulations_per_step"] == 5 * 40


def test_fig3_5(outdir):
    sizes = {"iterations_fig3": 60, "iterations_fig45": 60, "shown_fig3": 20, "kept_fig45": 20}
    summary = fig3_5_trajectories.run(outdir, seed=1, workers=1, sizes=sizes)
    check_files(outdir, summary)
    assert summary["fig3"]["targets"] == 5 and summary["fig45"]["targets"] == 3
    assert 0 <= summary["fig45"]["acceptance"] <= 1 and summary["fig45"]["mean_abs_bearing_error_deg"] >= 0


def test_table1_is_deterministic_across_workers(outdir):
    sizes = {"scenarios": 3, "particles": 30, "sensors": (16,), "targets": (2,)}
    summary = table1_rmse.run(outdir, seed=2, workers=2, sizes=sizes)
    check_files(outdir, summary)
    assert len(summary["cells"]) == 3 * 4 and len(summary["orderings"]) == 3
    for cell in summary["cells"]:
        assert cell["mean_rmse"] > 0 and cell["se"] >= 0
        assert (cell["paper_rmse"] is None) == (cell["algorithm"] == "mcmc")
    for o in summary["orderings"]:
        assert o["pt_lt_rw"] in ("holds", "holds in mean only", "reversed", "fails (not significant)")
        assert not math.isnan(o["pt_minus_rw"])
    again = table1_rmse.run(outdir, seed=2, workers=1, sizes=sizes)
    assert again["cells"] == summary["cells"]


def test_report_from_summaries(outdir):
    # runs after the experiments above (pytest keeps file order): rebuild from their JSON
    paper_main("abc", ["--out", str(outdir), "--report-only"])
    text = (outdir / "REPORT.md").read_text()
    for title, _ in report.SECTIONS.values():
        assert f"## {title}" in text
    assert "The full ordering holds in" in text and "· 9.70 (3.40)" in text
    for line in text.splitlines():
        if line.startswith("!["):
            assert (outdir / line.split("](")[1].rstrip(")")).is_file()
