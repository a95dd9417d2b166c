"""The context paper's experiments run end to end at tiny sizes and build REPORT.md."""

from __future__ import annotations

import json

from papers.context import exp_a_naive, exp_c_partial, floats_ridge, report


def test_experiments_and_report(tmp_path):
    tiny = {"repeats": 1, "particles": 60}
    a = exp_a_naive.run(tmp_path, sizes=tiny, workers=1)
    c = exp_c_partial.run(tmp_path, sizes=tiny, workers=1)
    f = floats_ridge.run(tmp_path, sizes={"repeats": 1, "days": 62, "particles": 100}, workers=1)
    for summary in (a, c, f):
        for name in summary["files"]:
            assert (tmp_path / name).stat().st_size > 0
        assert json.loads((tmp_path / f"{summary['name']}.json").read_text())["name"] == summary["name"]
    assert set(a["table"]) == {"none", "naive"} and c["unseen_steps"] > 0
    assert f["table"]["with"]["forbidden_positions"] == 0
    text = report.build_report(tmp_path).read_text()
    assert "Experiment A (Fig. 4)" in text and "Floats" in text and "| context at cell entry |" in text
