"""The mission overview (`overview.html`, `overview.csv`, `overview.png`): the table's values
against the floats' own files, the "needs a look" rules and order, `rafostrack summary`,
the page's escaping and atomic writing, and the map.

One tiny simulated mission (`m1`: 2 floats, 6 days, 60 particles) through `rafostrack batch`
with two extra rows in its floats.csv: `bad` (an arrival file that cannot be read: it fails)
and `later` (no arrival file: not tracked).
"""

from __future__ import annotations

import base64
import csv
import html
import json
import re
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from rafostrack.batch.overview import (
    OVERVIEW_COLUMNS,
    OVERVIEW_CSV,
    OVERVIEW_HTML,
    OVERVIEW_PNG,
    FloatRow,
    LookRules,
    Overview,
)
from rafostrack.batch.overview_page import overview_html
from rafostrack.batch.overview_rows import run_values, warning_counts
from rafostrack.batch.triage import judged
from rafostrack.cli import main
from rafostrack.config import load_config
from rafostrack.plots.base import figure
from rafostrack.plots.mission_map import NEEDS_LOOK, OK, FloatPath, draw_mission_map
from rafostrack.sim.mission_writer import write_mission
from rafostrack.sim.scenarios import synthetic_scenario
from rafostrack.sim.simulate import simulate_mission

TRACKED = ("sim1", "sim2")


@pytest.fixture(scope="module")
def archive(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("overview") / "archive"
    rng = np.random.default_rng(11)
    beacons, floats = synthetic_scenario(days=6, n_floats=2, rng=rng)
    mission = simulate_mission(beacons, floats, load_config().model, rng)
    write_mission(mission, root / "m1", {"filter": {"particles": 60}})
    table = root / "m1" / "floats.csv"
    first = table.read_text().splitlines()[1].split(",", 1)[1]
    with open(table, "a") as fh:
        fh.write(f"bad,{first}\nlater,{first}\n")
    (root / "m1" / "bad.csv").write_text("time,toa_s\nnot a time,12\n")
    return root


@pytest.fixture(scope="module")
def batch_out(archive, tmp_path_factory):
    out = tmp_path_factory.mktemp("overview-out") / "out"
    result = CliRunner().invoke(main, ["batch", str(archive), "--out", str(out), "--no-plots", "--jobs", "1"])
    assert result.exit_code == 1, result.output  # `bad` fails
    return out, result


def _rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def _summary(out: Path):
    return CliRunner().invoke(main, ["summary", str(out)])


# ----------------------------------------------------------------------------- batch + table


def test_a_batch_writes_the_overview_with_every_float(batch_out):
    out, result = batch_out
    assert (out / OVERVIEW_HTML).is_file() and (out / OVERVIEW_CSV).is_file()
    assert not (out / OVERVIEW_PNG).exists()  # --no-plots: no map
    assert "No map: the batch ran with --no-plots" in (out / OVERVIEW_HTML).read_text()
    rows = _rows(out / OVERVIEW_CSV)
    assert list(rows[0]) == list(OVERVIEW_COLUMNS)
    assert {r["float_id"] for r in rows} == {"bad", *TRACKED}  # `later` has no arrival file
    assert f"overview: {out / OVERVIEW_HTML}" in result.output  # the summary table names it
    assert "1 not tracked (no arrival file yet)" in (out / OVERVIEW_HTML).read_text()
    log = (out / "batch.log").read_text()
    assert re.search(r"overview: \d of 3 floats need a look \(m1/bad", log)


def test_the_table_matches_the_floats_files(batch_out):
    out, _ = batch_out
    rows = {r["float_id"]: r for r in _rows(out / OVERVIEW_CSV)}
    for float_id in TRACKED:
        row, where = rows[float_id], out / "m1" / float_id
        track = pd.read_parquet(where / "track.parquet")
        labels = pd.read_parquet(where / "labels.parquet")
        run = json.loads((where / "run.json").read_text())
        assert int(row["windows"]) == len(track)
        for status in ("ok", "ambiguous", "recovered", "unsupported"):
            assert float(row[f"share_{status}"]) == pytest.approx((track["status"] == status).mean(), abs=1e-4)
        assert float(row["sd_km_median"]) == pytest.approx(track["sd_km"].median(), abs=1e-3)
        assert float(row["sd_km_p95"]) == pytest.approx(np.percentile(track["sd_km"], 95), abs=1e-3)
        assert float(row["share_clutter"]) == pytest.approx(labels["beacon_id"].isna().mean(), abs=1e-4)
        assert float(row["share_labelled"]) + float(row["share_clutter"]) == pytest.approx(1.0, abs=1e-4)
        assert int(row["n_warnings"]) == len(run["warnings"])
        fitted = run["calibration"].get("values", {}) if run.get("calibration") else {}
        speed = fitted.get("[model] sound_speed_m_s", run["config"]["model"]["sound_speed_m_s"])
        assert float(row["sound_speed_m_s"]) == pytest.approx(speed)
        assert row["sound_speed_calibrated"] == ("true" if "[model] sound_speed_m_s" in fitted else "false")


def test_a_failed_float_comes_first_with_its_reason(batch_out):
    out, _ = batch_out
    rows = _rows(out / OVERVIEW_CSV)
    batch = {r["float_id"]: r for r in _rows(out / "batch-summary.csv")}
    assert rows[0]["float_id"] == "bad" and rows[0]["look"] == "failed"
    assert rows[0]["reasons"] == f"failed: {batch['bad']['reason']}"
    assert rows[0]["windows"] == "" and rows[0]["output"] == ""
    assert [r["look"] for r in rows[1:]] == sorted((r["look"] for r in rows[1:]), key=[NEEDS_LOOK, OK].index)


def test_a_contradicted_table_value_puts_its_float_ahead(batch_out, tmp_path):
    """With sim2's run.json saying its arrivals contradict a beacon's offset, `summary` lists
    sim2 right after the failed float, with the value, and needing a look."""
    out = Path(shutil.copytree(batch_out[0], tmp_path / "out"))
    path = out / "m1" / "sim2" / "run.json"
    run = json.loads(path.read_text())
    run["metadata_checks"].append(
        {"file": "/x/m1/beacons.csv", "line": 3, "id": "B1", "field": "offset_s", "given": 0.0,
         "supported": 30.5, "sd": 0.5, "unit": "s", "outcome": "contradicted", "used": 30.5}
    )  # fmt: skip
    path.write_text(json.dumps(run))
    for name in (OVERVIEW_CSV, OVERVIEW_HTML):
        (out / name).unlink()
    result = _summary(out)
    assert result.exit_code == 0, result.output
    rows = _rows(out / OVERVIEW_CSV)
    assert [r["float_id"] for r in rows[:2]] == ["bad", "sim2"]
    assert (
        rows[1]["look"] == NEEDS_LOOK and "arrivals contradict beacons.csv line 3: offset_s of B1" in rows[1]["reasons"]
    )
    assert rows[1]["metadata_contradicted"] == "beacons.csv line 3: offset_s of B1: given 0.0 s, arrivals 30.5 s"
    assert rows[1]["n_contradicted"] == "1"
    page = (out / OVERVIEW_HTML).read_text()  # and the mission's finding, as the batch prints it
    assert "<li>mission m1: beacons.csv line 3: field &#x27;offset_s&#x27; of source B1: given 0.0 s;" in page


# ------------------------------------------------------------------------------ the rules

_BASE = dict(windows=100, shares={"ok": 1.0}, sd_km_median=2.0, sd_km_p95=4.0, labelled_share=0.8, clutter_share=0.2)


@pytest.mark.parametrize(
    "change, reason",
    [
        (dict(shares={"ok": 0.89, "unsupported": 0.11}), "unsupported 11.0% of windows > 10%"),
        (dict(shares={"ok": 0.94, "ambiguous": 0.06}), "ambiguous 6.0% of windows > 5%"),
        (dict(shares={"ok": 0.97, "recovered": 0.03}), "recovered 3.0% of windows > 2%"),
        (dict(sd_km_p95=20.5), "p95 sd 20.5 km > 20 km"),
        (dict(clutter_share=0.6, labelled_share=0.4), "clutter 60.0% of TOAs > 50%"),
        (
            dict(contradicted=(("beacons.csv line 3: offset_s of B1", "given 0 s"), ("floats.csv: end_fix of f", ""))),
            "arrivals contradict beacons.csv line 3: offset_s of B1; floats.csv: end_fix of f",
        ),
        (dict(warning_kinds={"end fix": 1}), "end fix far from every particle"),
        (dict(windows=0, shares={}), "no window tracked"),
        (dict(unreadable="x/run.json: No such file"), "outputs unreadable: x/run.json: No such file"),
    ],
)
def test_each_rule_flags_its_float(change, reason):
    [ok] = judged([FloatRow("m", "f", **_BASE)], LookRules())
    [flagged] = judged([FloatRow("m", "f", **{**_BASE, **change})], LookRules())
    assert (ok.look, ok.reasons) == (OK, ())
    assert flagged.look == NEEDS_LOOK and flagged.reasons == (reason,)


def test_at_the_limit_is_not_above_it():
    at = dict(shares={"ok": 0.9, "unsupported": 0.1}, sd_km_p95=20.0, clutter_share=0.5)
    [row] = judged([FloatRow("m", "f", **{**_BASE, **at})], LookRules())
    assert row.look == OK


def test_order_failed_then_most_reasons_then_ok_by_mission_and_id():
    two = dict(shares={"ok": 0.8, "unsupported": 0.2}, sd_km_p95=30.0)
    one = dict(sd_km_p95=30.0)
    rows = [
        FloatRow("b", "ok2", **_BASE),
        FloatRow("a", "one", **{**_BASE, **one}),
        FloatRow("a", "ok1", **_BASE),
        FloatRow("z", "failed", failed="worker died"),
        FloatRow("b", "two", **{**_BASE, **two}),
        FloatRow("a", "one2", **{**_BASE, **one}),
    ]
    order = [(r.float_id, r.look) for r in judged(rows, LookRules())]
    assert order == [
        ("failed", "failed"),
        ("two", NEEDS_LOOK),
        ("one", NEEDS_LOOK),
        ("one2", NEEDS_LOOK),
        ("ok1", OK),
        ("ok2", OK),
    ]


def test_warnings_are_counted_by_the_kind_run_json_gives_them():
    """The kinds are read from run.json's `warning_kinds` (set where each warning was made),
    never from the wording; a run.json without them (an older version), or whose kinds do
    not pair with its warnings, counts each warning as "other"."""
    warnings = ["a", "b", "c", "d"]
    kinds = ["metadata", "end fix", "metadata", "gaps"]
    assert warning_counts({"warnings": warnings, "warning_kinds": kinds}) == {"metadata": 2, "end fix": 1, "gaps": 1}
    older = {"warnings": ["f1: the end fix is 80.2 km from every particle (16 sd); its sd was widened to 40.0 km"]}
    assert warning_counts(older) == {"other": 1}
    assert warning_counts({**older, "warning_kinds": ["end fix", "gaps"]}) == {"other": 1}
    assert warning_counts({"warnings": [], "warning_kinds": []}) == warning_counts({}) == {}


def _with_warnings(out: Path, float_id: str, warnings: list[str], kinds: list[str]) -> None:
    path = out / "m1" / float_id / "run.json"
    run = json.loads(path.read_text())
    run["warnings"], run["warning_kinds"] = warnings, kinds
    path.write_text(json.dumps(run))


def test_rewording_a_warning_leaves_the_triage_unchanged(batch_out, tmp_path):
    """Two copies of a tree whose sim2 warns of the same kinds (an end fix far from every
    particle, a contradicted table value, a gap) in entirely different words: `summary`
    gives both the same look, reasons and warning counts (the kind, not the wording, is read)."""
    kinds = ["end fix", "metadata", "gaps"]
    wordings = {
        "today": [
            "sim2: the end fix is 80.2 km from every particle (16 sd); its sd was widened to 40.0 km",
            "floats.csv: line 3: field 'clock_offset_end_s' of sim2 is empty; estimated from the arrivals: -2 s",
            "sim2.csv: no usable beacon (no window with an active beacon and a stored TOA) for more than 10 days: x",
        ],
        "reworded": ["the surfacing position disagrees with the cloud", "a float table cell was filled in", "silence"],
    }
    rows = {}
    for name, warnings in wordings.items():
        out = Path(shutil.copytree(batch_out[0], tmp_path / name))
        _with_warnings(out, "sim2", warnings, kinds)
        result = _summary(out)
        assert result.exit_code == 0, result.output
        rows[name] = next(r for r in _rows(out / OVERVIEW_CSV) if r["float_id"] == "sim2")
    triage = ("look", "reasons", "n_warnings", "warning_kinds")
    assert {k: rows["reworded"][k] for k in triage} == {k: rows["today"][k] for k in triage}
    assert rows["reworded"]["look"] == NEEDS_LOOK and "end fix far from every particle" in rows["reworded"]["reasons"]
    assert rows["reworded"]["warning_kinds"] == "end fix=1;gaps=1;metadata=1"


def test_run_values_read_the_calibration_the_clock_and_the_contradictions():
    run = {
        "float_id": "f1",
        "config": {"model": {"sound_speed_m_s": 1480.0, "toa_sigma_s": 2.0}},
        "calibration": {"values": {"[model] sound_speed_m_s": 1475.5}, "residual_rms_s": 1.7},
        "metadata_checks": [
            {"file": "a/floats.csv", "line": 2, "id": "f1", "field": "clock_offset_start_s", "given": 1.0,
             "supported": 0.9, "unit": "s", "outcome": "consistent", "used": 1.0},
            {"file": "a/floats.csv", "line": 2, "id": "f1", "field": "clock_offset_end_s", "given": None,
             "supported": -4.5, "unit": "s", "outcome": "estimated", "used": -4.5},
            {"file": "a/floats.csv", "line": 2, "id": "f1", "field": "end_fix", "given": 0.0, "supported": 40.2,
             "unit": "km", "outcome": "contradicted", "used": 40.2, "given_lat_lon": [-58.0, -100.0],
             "supported_lat_lon": [-58.3, -100.2]},
        ],
        "warnings": ["f1: the end fix is 80.2 km from every particle (16 sd); its sd was widened to 40.0 km"],
        "warning_kinds": ["end fix"],
    }  # fmt: skip
    values = run_values(run, "f1")
    assert (values["sound_speed_m_s"], values["sound_speed_calibrated"]) == (1475.5, True)
    assert (values["toa_sigma_s"], values["toa_sigma_calibrated"]) == (2.0, False)
    assert values["toa_residual_rms_s"] == 1.7
    assert values["clock_drift_s"] == pytest.approx(-5.5)
    assert values["warning_kinds"] == {"end fix": 1}
    assert values["contradicted"] == (
        ("floats.csv line 2: end_fix of f1", "given -58.000, -100.000, arrivals -58.300, -100.200 (40.2 km away)"),
    )
    assert run_values({"float_id": "f1"}, "f1")["clock_drift_s"] is None  # no checks: unknown, not 0


# ------------------------------------------------------------------------ summary and the page


@pytest.mark.parametrize("make", ["missing", "empty", "other files"])
def test_summary_of_a_folder_without_a_tracked_float_is_a_one_line_error(tmp_path, make):
    out = tmp_path / "out"
    if make != "missing":
        out.mkdir()
    if make == "other files":
        (out / "f1").mkdir()
        (out / "f1" / "run.json").write_text("{}")  # no track.parquet: not a tracked float
        (out / "notes.txt").write_text("x")
    result = _summary(out)
    assert result.exit_code == 2
    assert result.stdout == ""
    [line] = result.stderr.splitlines()
    assert line.startswith(f"rafostrack: error: {out}: ")
    assert ("does not exist" if make == "missing" else "holds no tracked float") in line
    assert not (out / OVERVIEW_HTML).exists()


def test_summary_of_a_track_folder(batch_out, tmp_path):
    """`rafostrack track --out OUT` leaves OUT/<float_id>/: one float, no mission; the map is drawn."""
    out = tmp_path / "out"
    shutil.copytree(batch_out[0] / "m1" / "sim1", out / "sim1")
    result = _summary(out)
    assert result.exit_code == 0, result.output
    [row] = _rows(out / OVERVIEW_CSV)
    assert (row["mission"], row["float_id"]) == ("", "sim1")
    png = (out / OVERVIEW_PNG).read_bytes()
    assert png.startswith(b"\x89PNG")
    assert f"data:image/png;base64,{base64.b64encode(png).decode()}" in (out / OVERVIEW_HTML).read_text()


def test_the_page_is_written_atomically_and_holds_every_float(batch_out, tmp_path, atomic_writes):
    out = Path(shutil.copytree(batch_out[0], tmp_path / "out"))
    (out / OVERVIEW_HTML).unlink()
    result = _summary(out)
    assert result.exit_code == 0, result.output
    assert {out / OVERVIEW_HTML, out / OVERVIEW_CSV} <= set(atomic_writes)
    assert not list(out.glob(".*.tmp"))
    page = (out / OVERVIEW_HTML).read_text()
    body = page.split("<tbody>")[1].split("</tbody>")[0]
    assert body.count("<tr") == 3
    for float_id in ("bad", *TRACKED):
        assert f">{float_id}<" in body
    assert 'href="m1/sim1/' in body  # a tracked float links to its outputs


def test_the_page_escapes_what_it_shows(tmp_path):
    row = FloatRow(
        "<script>alert(1)</script>",
        'f"1&<b>',
        output=str(tmp_path / "a b"),
        failed="bad <input> & more",
    )
    page = overview_html(Overview(tmp_path, judged([row], LookRules())), None)
    assert "<script>alert(1)" not in page and "<b>" not in page and "<input>" not in page
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in page
    assert "f&quot;1&amp;&lt;b&gt;" in page
    assert "failed: bad &lt;input&gt; &amp; more" in page
    assert page.count("<script>") == 1  # the page's own sorting script only


# -------------------------------------------------------------------------------- the map


def _no_coast(*_args) -> None:
    pass


def test_the_map_draws_floats_needing_a_look_on_top_and_names_them():
    t = np.linspace(0.0, 1.0, 20)
    paths = [
        FloatPath("calm", -58.0 + t, -100.0 + t, OK),
        FloatPath("odd", -57.0 - t, 179.5 + t, NEEDS_LOOK),  # crosses the dateline
        FloatPath("odd2", -57.5 - t, -179.0 + t, NEEDS_LOOK),
    ]
    beacons = pd.DataFrame({"beacon_id": ["B1"], "lat": [-58.5], "lon": [-179.0]})
    with figure() as fig:
        draw_mission_map(fig, paths[1:], beacons, "title", background=_no_coast)
        ax = fig.axes[0]
        x0, x1 = ax.get_xlim()
        assert x1 - x0 < 10.0  # one piece across the dateline, not 360 degrees wide
        names = {t.get_text() for t in ax.texts}
        assert {"odd", "odd2", "B1"} <= names
    with figure() as fig:
        draw_mission_map(fig, paths, beacons, "title", background=_no_coast)
        ax = fig.axes[0]
        tracks = [line for line in ax.lines if len(line.get_xdata()) == 20]
        assert [line.get_linestyle() for line in tracks] == ["-", "--", "--"]  # ok below
        legend = [t.get_text() for t in fig.legends[0].get_texts()]
        assert legend[:2] == ["ok (1)", "needs a look (2)"]


def test_every_float_has_its_own_colour_and_its_status_a_line_style():
    """Tangled tracks are told apart by colour; whether a float needs a look, by its dashed
    line and the cross at its end (the legend shows the styles)."""
    t = np.linspace(0.0, 1.0, 20)
    paths = [FloatPath(f"f{k}", -58.0 + 0.3 * np.sin(3 * t + k), -90.0 + t, OK) for k in range(6)]
    paths.append(FloatPath("odd", -58.0 + t, -90.0 + t, NEEDS_LOOK))
    with figure() as fig:
        draw_mission_map(fig, paths, None, "title", background=_no_coast)
        ax = fig.axes[0]
        tracks = [line for line in ax.lines if len(line.get_xdata()) == 20]
        assert len({line.get_color() for line in tracks}) == len(paths)
        assert [line.get_linestyle() for line in tracks] == ["-"] * 6 + ["--"]
        assert [line.get_marker() for line in ax.lines if len(line.get_xdata()) == 1 and line.get_marker() == "X"]
        legend = {
            t.get_text(): h for t, h in zip(fig.legends[0].get_texts(), fig.legends[0].legend_handles, strict=True)
        }
        assert legend["ok (6)"].get_linestyle() == "-" and legend["needs a look (1)"].get_linestyle() == "--"


@pytest.mark.parametrize("below_deg", [0.05, 0.1, 0.15, 0.2])
def test_float_names_stay_off_the_beacons_names(below_deg):
    """A float ending a little below a beacon: its name (above its end) would cover the
    beacon's (below the triangle); it goes elsewhere, and both stay inside the map."""
    t = np.linspace(0.0, 1.0, 10)
    paths = [FloatPath("calm", -58.0 - below_deg - 0.5 + 0.5 * t, -90.5 + 0.5 * t)]
    beacons = pd.DataFrame({"beacon_id": ["B1", "B2"], "lat": [-58.0, -56.0], "lon": [-90.0, -92.0]})
    with figure() as fig:
        draw_mission_map(fig, paths, beacons, "t", background=_no_coast)
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        ax = fig.axes[0]
        frame = ax.get_window_extent(renderer)
        boxes = {t.get_text(): t.get_window_extent(renderer) for t in ax.texts}
        assert not boxes["calm"].overlaps(boxes["B1"])
        assert all(
            frame.x0 <= b.x0 and b.x1 <= frame.x1 and frame.y0 <= b.y0 and b.y1 <= frame.y1 for b in boxes.values()
        )


def _css_rule(page: str, selector: str) -> str:
    """The declarations of the page's CSS rule for `selector` ("" when none)."""
    style = page.split("<style>")[1].split("</style>")[0]
    found = re.search(r"(?m)^" + re.escape(selector) + r" \{([^}]*)\}", style)
    return found.group(1) if found else ""


def _text(cell: str) -> str:
    """A table cell's text as shown (tags dropped, entities read)."""
    return html.unescape(re.sub(r"<[^>]+>", "", cell)).strip()


def _longest_word(text: str) -> int:
    return max((len(w) for w in text.split()), default=0)


def _min_table_width_px(page: str) -> float:
    """The narrowest the page's table can be laid out, roughly as a browser does: per column
    its widest unbreakable run (a cell that must stay on one line whole, else its longest
    word; one character where the CSS lets text break anywhere), at 0.65 em a character
    (0.7 em for the bold headers), plus padding and border."""
    font_px = float(re.search(r"font-size: (\d+)px", _css_rule(page, "table.overview")).group(1))
    pad_px = float(
        re.search(r"padding: \d+px (\d+)px", _css_rule(page, "table.overview th, table.overview td")).group(1)
    )
    th_nowrap = "nowrap" in _css_rule(page, "table.overview th")
    td_anywhere = "overflow-wrap: anywhere" in _css_rule(page, "table.overview td")
    table = page.split('<table class="overview">')[1].split("</table>")[0]
    widths = [
        0.7 * font_px * (len(_text(h)) if th_nowrap else _longest_word(_text(h)))
        for h in re.findall(r"<th>(.*?)</th>", table)
    ]
    for row in re.findall(r"<tr class=.*?</tr>", table):
        for k, (attrs, cell) in enumerate(re.findall(r"<td([^>]*)>(.*?)</td>", row)):
            whole = 'class="num"' in attrs
            chars = len(_text(cell)) if whole else 1 if td_anywhere else _longest_word(_text(cell))
            widths[k] = max(widths[k], 0.65 * font_px * chars)
    return sum(widths) + len(widths) * (2 * pad_px + 1) + 1


def test_the_table_fits_a_1400_px_window_and_scrolls_in_its_box_beyond(batch_out, tmp_path):
    """At 1400 px (less the page's margins and a scroll bar) the table needs no horizontal
    scrolling, even with a failed float's long reason; a wider table scrolls inside its own
    box, never widening the page."""
    out, _ = batch_out
    long_reason = "cannot read /data/archive/" + "a_very_long_folder_name/" * 6 + "float.csv: no such file"
    row = FloatRow("m1", "x" * 24, failed=long_reason)
    for page in (
        (out / OVERVIEW_HTML).read_text(),
        overview_html(Overview(tmp_path, judged([row], LookRules())), None),
    ):
        assert _min_table_width_px(page) <= 1400 - 2 * 1.5 * 14 - 2 - 16
        box = re.search(r'<div class="([^"]+)">\s*<table class="overview">', page)
        assert box and "</table>\n</div>" in page
        rule = _css_rule(page, f"div.{box.group(1)}")
        assert "max-width: 100%" in rule and re.search(r"overflow(-x)?: auto", rule)


def test_summary_from_another_folder_finds_the_relative_beacon_table_or_says_so(archive, tmp_path, monkeypatch):
    """`rafostrack track m1/sim1.csv --out out` run in WORK records m1/beacons.csv, relative
    to WORK, in run.json. `summary WORK/out` run elsewhere still draws those beacons; with
    the mission moved away it draws none and says so in one warning line."""
    import rafostrack.batch.overview as overview_module

    work, elsewhere = tmp_path / "work", tmp_path / "elsewhere"
    shutil.copytree(archive / "m1", work / "m1")
    elsewhere.mkdir()
    monkeypatch.chdir(work)
    tracked = CliRunner().invoke(main, ["track", "m1/sim1.csv", "--out", "out", "--no-plots"])
    assert tracked.exit_code == 0, tracked.output
    assert json.loads((work / "out" / "sim1" / "run.json").read_text())["inputs"]["beacons"]["path"] == "m1/beacons.csv"
    drawn = []
    original = overview_module.plot_mission_map
    monkeypatch.setattr(
        overview_module,
        "plot_mission_map",
        lambda paths, beacons, *a: drawn.append(beacons) or original(paths, beacons, *a),
    )
    monkeypatch.chdir(elsewhere)
    result = _summary(work / "out")
    assert result.exit_code == 0, result.output
    assert drawn[-1] is not None and len(drawn[-1]) == len(pd.read_csv(work / "m1" / "beacons.csv"))
    assert "warning" not in result.stderr
    shutil.move(work / "m1", tmp_path / "moved")
    result = _summary(work / "out")
    assert result.exit_code == 0, result.output
    assert drawn[-1] is None
    [line] = result.stderr.splitlines()
    assert line.startswith("rafostrack: warning: overview.png: ") and "m1/beacons.csv" in line
