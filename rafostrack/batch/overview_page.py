"""The mission overview's page, overview.html: counts, the map inline, the sortable table, each
mission's array fit (`overview_array.py`), the rules.

One self-contained file (no network): the map's PNG inline as base64, the table sorted by a
click on a column's header (a few lines of script), every value escaped. Floats that need a
look come first (`triage.judged`); values kept as configured (not calibrated) are greyed.
"""

from __future__ import annotations

import base64
import html
import os
from datetime import UTC, datetime
from pathlib import Path
from urllib.parse import quote

from .. import __version__
from ..plots.mission_map import NEEDS_LOOK, OK
from .overview_array import arrays_count_text, arrays_html
from .overview_rows import OVERVIEW_CSV, STATUSES, FloatRow, kinds_text
from .plan import FAILED
from .triage import LOOK_ORDER, Overview

OVERVIEW_HTML = "overview.html"


def map_title(overview: Overview) -> str:
    """'3 floats tracked: 1 needs a look' (and the failed ones, not on the map)."""
    tracked = [r for r in overview.rows if r.look != FAILED]
    needs = sum(r.look == NEEDS_LOOK for r in tracked)
    failed = overview.count(FAILED)
    text = f"{len(tracked)} float{'s' if len(tracked) != 1 else ''} tracked: "
    text += f"{needs} need{'s' if needs == 1 else ''} a look"
    return text + (f"; {failed} failed (not drawn)" if failed else "")


# The table fits the window: headers wrap between words, text cells anywhere (a long path
# too), only numbers stay on one line; wider still (a narrow window), it scrolls inside its
# box, the page never wider than the window, the header row kept in view.
_STYLE = """
body { font: 14px/1.4 system-ui, sans-serif; margin: 1.5em; color: #222; }
img.map { max-width: 100%; border: 1px solid #ccc; }
div.table-box { max-width: 100%; max-height: 85vh; overflow: auto; border: 1px solid #ddd; }
table.overview { border-collapse: collapse; font-size: 12px; width: 100%; }
table.overview th, table.overview td { border: 1px solid #ddd; padding: 3px 5px; vertical-align: top; }
table.overview td { overflow-wrap: anywhere; }
table.overview th { background: #f0f0f0; cursor: pointer; position: sticky; top: 0; white-space: normal; }
table.overview th[data-order=asc]::after { content: " \\25B2"; }
table.overview th[data-order=desc]::after { content: " \\25BC"; }
table.overview td.num { text-align: right; white-space: nowrap; }
tr.failed td { background: #f8d7d7; }
tr.needs td { background: #fdeeee; }
td .configured { color: #888; }
table.array { border-collapse: collapse; font-size: 12px; }
table.array th, table.array td { border: 1px solid #ddd; padding: 3px 5px; vertical-align: top; }
table.array th { background: #f0f0f0; }
table.array td.num { text-align: right; white-space: nowrap; }
tr.contradicted td { background: #fdeeee; }
"""

# Click a header: sort the rows by that column (numbers by value, text alphabetically, empty
# cells last), again to reverse. Each cell's sort key is its data-sort attribute, else its text.
_SCRIPT = """
(function () {
  function key(cell) {
    var k = cell.hasAttribute("data-sort") ? cell.getAttribute("data-sort") : cell.textContent.trim();
    var n = Number(k);
    return k === "" ? null : (isFinite(n) ? n : k.toLowerCase());
  }
  var table = document.querySelector("table.overview");
  var heads = table.tHead.rows[0].cells;
  Array.prototype.forEach.call(heads, function (th, col) {
    th.addEventListener("click", function () {
      var asc = th.getAttribute("data-order") !== "asc";
      Array.prototype.forEach.call(heads, function (h) { h.removeAttribute("data-order"); });
      th.setAttribute("data-order", asc ? "asc" : "desc");
      var body = table.tBodies[0];
      var rows = Array.prototype.slice.call(body.rows);
      rows.sort(function (a, b) {
        var x = key(a.cells[col]), y = key(b.cells[col]);
        if (x === null || y === null) { return (x === null) - (y === null); }
        if (typeof x !== typeof y) { x = String(x); y = String(y); }
        return (x < y ? -1 : x > y ? 1 : 0) * (asc ? 1 : -1);
      });
      rows.forEach(function (r) { body.appendChild(r); });
    });
  });
})();
"""

# The table's columns: header, and the cell of a row as (text, sort key, is a number).
_PERCENT = "{:.1%}"


def _esc(value: object) -> str:
    return html.escape(str(value), quote=True)


def _td(text: str, sort: object = None, num: bool = False, inner_html: str | None = None) -> str:
    """A cell: `text` escaped (or `inner_html`, already escaped), its sort key as data-sort."""
    attrs = ' class="num"' if num else ""
    if sort is not None:
        attrs += f' data-sort="{_esc(sort)}"'
    return f"<td{attrs}>{inner_html if inner_html is not None else _esc(text)}</td>"


def _num_td(value: float | int | None, fmt: str = "{:.1f}", configured: bool = False) -> str:
    """A number's cell, empty when unknown; a value kept as configured (not calibrated) greyed."""
    if value is None:
        return _td("", "", num=True)
    text = _esc(fmt.format(value))
    if configured:
        text = f'<span class="configured" title="as configured, not calibrated">{text}</span>'
    return _td("", value, num=True, inner_html=text)


def _float_link(overview: Overview, row: FloatRow) -> str:
    """The float id, linked to its track.png (else its folder) relative to the page."""
    if not row.output:
        return _td(row.float_id)
    target = Path(row.output) / "track.png"
    target = target if target.is_file() else Path(row.output)
    href = quote(Path(os.path.relpath(target, overview.out)).as_posix() + ("/" if target.is_dir() else ""))
    return _td(row.float_id, row.float_id, inner_html=f'<a href="{_esc(href)}">{_esc(row.float_id)}</a>')


_HEADERS = (
    "look", "mission", "float", "why", "windows", "ok", "ambiguous", "recovered", "unsupported",
    "sd median (km)", "sd p95 (km)", "labelled", "clutter", "sound speed (m/s)", "clock drift (s)",
    "TOA sd (s)", "TOA rms (s)", "warnings", "contradicted table values",
)  # fmt: skip


def _row_html(overview: Overview, row: FloatRow) -> str:
    """One table row: the float's cells in `_HEADERS` order."""
    known = row.windows is not None and not row.unreadable
    cells = [
        _td(row.look, LOOK_ORDER[row.look]),
        _td(row.mission),
        _float_link(overview, row),
        _td("; ".join(row.reasons)),
        _num_td(row.windows, "{:d}"),
        *(_num_td(row.shares.get(s, 0.0) if known else None, _PERCENT) for s in STATUSES),
        _num_td(row.sd_km_median),
        _num_td(row.sd_km_p95),
        _num_td(row.labelled_share, _PERCENT),
        _num_td(row.clutter_share, _PERCENT),
        _num_td(row.sound_speed_m_s, "{:.1f}", configured=row.sound_speed_calibrated is False),
        _num_td(row.clock_drift_s, "{:.2f}"),
        _num_td(row.toa_sigma_s, "{:.2f}", configured=row.toa_sigma_calibrated is False),
        _num_td(row.toa_residual_rms_s, "{:.2f}"),
        _td(_warnings_text(row) if known else "", row.n_warnings if known else ""),
        _td(row.contradicted_text(), len(row.contradicted) if known else ""),
    ]
    css = {FAILED: "failed", NEEDS_LOOK: "needs", OK: "ok"}[row.look]
    return f'<tr class="{css}">' + "".join(cells) + "</tr>"


def _warnings_text(row: FloatRow) -> str:
    """'3: metadata 2, gaps 1', or '0'."""
    return f"{row.n_warnings}: {kinds_text(row.warning_kinds)}" if row.n_warnings else "0"


def _counts_text(overview: Overview) -> str:
    """'3 floats: 1 needs a look (of which 1 failed), 2 ok; 1 not tracked (no arrival file).'
    and, with an array fit, ' Array fit: 2 table values decided.'"""
    n, failed, needs, ok = len(overview.rows), overview.count(FAILED), overview.count(NEEDS_LOOK), overview.count(OK)
    text = f"{n} float{'s' if n != 1 else ''}: {needs + failed} need{'s' if needs + failed == 1 else ''} a look"
    text += f" (of which {failed} failed), {ok} ok" if failed else f", {ok} ok"
    if overview.not_tracked:
        text += f"; {overview.not_tracked} not tracked (no arrival file yet)"
    return " ".join(filter(None, (text + ".", arrays_count_text(overview.arrays))))


def overview_html(overview: Overview, png: bytes | None) -> str:
    """The page: counts, the map (the PNG inline), the sortable table, the array fits, the rules."""
    title = f"Mission overview: {overview.out}"
    image = (
        f'<p><img class="map" alt="{_esc(map_title(overview))}" '
        f'src="data:image/png;base64,{base64.b64encode(png).decode("ascii")}"></p>'
        if png
        else "<p><em>No map: the batch ran with --no-plots.</em></p>"
    )
    head = "".join(f"<th>{_esc(h)}</th>" for h in _HEADERS)
    body = "\n".join(_row_html(overview, r) for r in overview.rows)
    rules = "".join(f"<li>{_esc(rule)}</li>" for rule in overview.rules.describe())
    findings = "".join(f"<li>{_esc(line)}</li>" for line in overview.findings)
    if findings:
        findings = f"<h2>Table values the arrivals contradict</h2>\n<ul>{findings}</ul>"
    stamp = datetime.now(UTC).isoformat(timespec="seconds")
    return f"""<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>{_esc(title)}</title>
<style>{_STYLE}</style>
</head>
<body>
<h1>{_esc(title)}</h1>
<p><strong>{_esc(_counts_text(overview))}</strong> Floats that need a look come first; click a
column's header to sort by it, again to reverse. A float's name opens its track plot; greyed
values are as configured, not calibrated. The same table is in {_esc(OVERVIEW_CSV)}.</p>
{image}
{findings}
<div class="table-box">
<table class="overview">
<thead><tr>{head}</tr></thead>
<tbody>
{body}
</tbody>
</table>
</div>
{arrays_html(overview.arrays)}
<h2>A float needs a look when</h2>
<ul>{rules}</ul>
<p>Shares of windows by track status (ok, ambiguous, recovered, unsupported); sd: the
posterior's RMS distance from the position (median and 95th percentile over the windows);
labelled and clutter: shares of the float's TOAs; clock drift: the float clock's end offset
minus its launch offset, as tracked; TOA sd: the arrival-time noise the tracker used; TOA
rms: the calibration's residual RMS of the direct arrivals.</p>
<p><small>Written by rafostrack {_esc(__version__)} at {_esc(stamp)}.</small></p>
<script>{_SCRIPT}</script>
</body>
</html>
"""
