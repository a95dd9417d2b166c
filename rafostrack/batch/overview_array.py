"""The mission overview's array section: what each mission's array fit left in OUT/<mission>.

The array fit (`array_rounds.py`, `mission/outputs.py`) writes `array.csv` (per source and
field: given, estimated, sd, outcome, the value the calibrated table holds where it changed
it), `array.json` (its rounds), `array.png` and, when it decided a value,
`beacons-calibrated.csv`. Read back
here, each file's failure kept as one line of text (never raised); a mission without
array.csv has no section. A section: one line (the rounds, what was decided, linked to the
calibrated table), the values the arrivals do not call consistent, links to array.png and
array.csv (relative to the page; the plot is not inlined: it can be large).
"""

from __future__ import annotations

import csv
import html
import json
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import Any
from urllib.parse import quote

from ..mission.outputs import ARRAY_NAME, ARRAY_PLOT_NAME, CALIBRATED_NAME
from .array_rounds import ARRAY_JSON, MAX_ROUNDS

ARRAY_TITLE = "The array, as the mission fitted it"
# array.csv's columns shown for a value not consistent (and `calibrated`, read for the line)
_SHOWN = ("source", "field", "given", "estimated", "sd", "unit", "outcome", "floats", "arrivals")
_NUMERIC = {"given", "estimated", "sd", "floats", "arrivals"}


@dataclass(frozen=True)
class ArraySection:
    """One mission's array fit as its files say: array.csv's rows, array.json's rounds."""

    mission: str
    values: tuple[dict[str, str], ...] | None  # array.csv's rows; None: it cannot be read
    rounds: tuple[dict[str, Any], ...] = ()  # array.json's rounds, in order
    table: dict[str, dict[str, str]] | None = None  # beacons-calibrated.csv's rows by beacon_id
    problems: tuple[str, ...] = ()  # the files that cannot be read, one line each
    plot: bool = False  # array.png is there

    @property
    def decided(self) -> list[dict[str, str]]:
        """The values the calibrated table changed (array.csv's `calibrated`: the value it holds)."""
        return [v for v in self.values or () if v["calibrated"]]

    @property
    def not_consistent(self) -> list[dict[str, str]]:
        """The values the arrivals contradict or leave undetermined."""
        return [v for v in self.values or () if v["outcome"] != "consistent"]


# ----------------------------------------------------------------------------- reading


def mission_arrays(out: Path, missions: Iterable[str]) -> tuple[ArraySection, ...]:
    """The array section of each mission (each once, in the order given) with an array.csv."""
    sections = (read_array(Path(out) / mission, mission) for mission in dict.fromkeys(missions))
    return tuple(s for s in sections if s is not None)


def read_array(folder: Path, mission: str) -> ArraySection | None:
    """What the mission's array fit left in `folder` (None: no array.csv there)."""
    if not (folder / ARRAY_NAME).is_file():
        return None
    values, why = _read_csv(folder / ARRAY_NAME, (*_SHOWN, "calibrated"))
    if values is None:
        return ArraySection(mission, None, problems=(why,))
    rounds, why_rounds = _read_rounds(folder / ARRAY_JSON)
    table, why_table = None, ""
    if (folder / CALIBRATED_NAME).is_file():
        rows, why_table = _read_csv(folder / CALIBRATED_NAME, ("beacon_id",))
        table = None if rows is None else {row["beacon_id"]: row for row in rows}
    problems = tuple(p for p in (why_rounds, why_table) if p)
    return ArraySection(mission, tuple(values), rounds, table, problems, (folder / ARRAY_PLOT_NAME).is_file())


def _read_csv(path: Path, required: Sequence[str]) -> tuple[list[dict[str, str]] | None, str]:
    """A CSV file's rows (names and cells stripped); None and why when it cannot be read or
    lacks one of the `required` columns."""
    try:
        with open(path, encoding="utf-8", newline="") as fh:
            reader = csv.DictReader(fh, restval="")
            rows = [{k.strip(): (v or "").strip() for k, v in row.items() if isinstance(k, str)} for row in reader]
            columns = [name.strip() for name in reader.fieldnames or ()]
    except (OSError, ValueError, csv.Error) as exc:
        return None, f"{path.name} cannot be read: {_why(exc)}"
    missing = [name for name in required if name not in columns]
    if missing:
        return None, f"{path.name} cannot be read: no column {', '.join(missing)}"
    return rows, ""


def _read_rounds(path: Path) -> tuple[tuple[dict[str, Any], ...], str]:
    """array.json's rounds; none and why when it cannot be read."""
    try:
        record = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        return (), f"{path.name} cannot be read: {_why(exc)}"
    rounds = record.get("rounds") if isinstance(record, dict) else None
    if not isinstance(rounds, list):
        return (), f"{path.name} cannot be read: no list of rounds"
    return tuple(r for r in rounds if isinstance(r, dict)), ""


def _why(exc: Exception) -> str:
    """An error in a few words: an OS error's own words (not its path), else its message."""
    return exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)


# ---------------------------------------------------------------------------- the page


def _esc(value: object) -> str:
    """`value` as HTML text (quotes escaped too, for attributes)."""
    return html.escape(str(value), quote=True)


def _link(section: ArraySection, name: str) -> str:
    """A link to the mission's file `name`, relative to the page (in the output root)."""
    href = quote(str(PurePosixPath(section.mission or ".") / name))
    return f'<a href="{_esc(href)}">{_esc(name)}</a>'


def arrays_count_text(sections: Sequence[ArraySection]) -> str:
    """'Array fit: 6 table values decided.' (of several missions: their sum); '' without one."""
    if not sections:
        return ""
    n_decided = sum(len(s.decided) for s in sections)
    text = f"{n_decided} table value{'s' if n_decided != 1 else ''} decided" if n_decided else "no table value decided"
    unread = sum(s.values is None for s in sections)
    text += f"; {unread} {ARRAY_NAME} cannot be read" if unread else ""
    return f"Array fit{f's of {len(sections)} missions' if len(sections) > 1 else ''}: {text}."


def arrays_html(sections: Sequence[ArraySection]) -> str:
    """The page's array sections, one per mission ('' without one)."""
    return "\n".join(section_html(s) for s in sections)


def section_html(section: ArraySection) -> str:
    """One mission's section: its heading, the line, the values not consistent, the links."""
    title = f"{ARRAY_TITLE}: {section.mission}" if section.mission else ARRAY_TITLE
    parts = [f"<h2>{_esc(title)}</h2>", *(f"<p><em>{_esc(p)}</em></p>" for p in section.problems)]
    if section.values is None:
        return "\n".join(parts)
    parts += [f"<p>{_esc(_rounds_text(section.rounds))}: {_decided_html(section)}.</p>", _values_html(section)]
    plot = f"{_link(section, ARRAY_PLOT_NAME)}: each source's arrival residuals against time, before and after the fit"
    if not section.plot:
        plot = f"no {_esc(ARRAY_PLOT_NAME)} (the batch ran with --no-plots)"
    return "\n".join([*parts, f"<p>{plot}; {_link(section, ARRAY_NAME)}: every value.</p>"])


def _rounds_text(rounds: Sequence[dict[str, Any]]) -> str:
    """'3 rounds; in the last, 24 floats fit the array, their weighted rms residual 1.89 s',
    and how many float's arrivals of a source it set aside, if any."""
    if not rounds:
        return "rounds not known"
    floats, rms_s = rounds[-1].get("floats", "?"), rounds[-1].get("rms_residual_s")
    rms = f"{rms_s:.2f} s" if isinstance(rms_s, int | float) and not isinstance(rms_s, bool) else "not known"
    text = f"{len(rounds)} round{'s' if len(rounds) != 1 else ''}; in the last, "
    text += f"{floats} float{'s' if floats != 1 else ''} fit the array, their weighted rms residual {rms}"
    aside = rounds[-1].get("set_aside")
    if isinstance(aside, list) and aside:
        text += f", {len(aside)} float's arrivals of a source set aside as outliers among its floats ({ARRAY_JSON})"
    return text


def _decided_html(section: ArraySection) -> str:
    """'decided in beacons-calibrated.csv (linked): US1-1 drift_s_per_day 0.0396 → 0.01573
    s/day, ...; settled: ...', or 'no table value decided'."""
    if not section.decided:
        return "no table value decided"
    where = _link(section, CALIBRATED_NAME) if section.table is not None else _esc(CALIBRATED_NAME)
    changes = ", ".join(_change_text(section, value) for value in section.decided)
    return f"decided in {where}: {_esc(changes)}{_esc(_settled_text(section.rounds))}"


def _change_text(section: ArraySection, value: dict[str, str]) -> str:
    """'US1-1 drift_s_per_day 0.0396 → 0.01573 s/day': given, then as the calibrated table holds it."""
    return f"{value['source']} {value['field']} {value['given']} → {value['calibrated']} {value['unit']}"


def _settled_text(rounds: Sequence[dict[str, Any]]) -> str:
    """Whether the floats were tracked with the decided table (array_rounds.round_line's words)."""
    if not rounds:
        return ""
    if rounds[-1].get("settled") is True:
        return "; settled: the floats were tracked with these values"
    if len(rounds) >= MAX_ROUNDS:
        return f"; not settled after {len(rounds)} rounds: the floats keep the table of the round before"
    return "; not settled"


def _values_html(section: ArraySection) -> str:
    """The values not consistent with the arrivals, as a table; one line when there is none."""
    values, odd = section.values or (), section.not_consistent
    if not values:
        return f"<p>{ARRAY_NAME} holds no value.</p>"
    if not odd:
        return f"<p>All {len(values)} values are consistent with the arrivals.</p>"
    head = "".join(f"<th>{_esc(name)}</th>" for name in _SHOWN)
    body = "\n".join(_value_row(v) for v in odd)
    return (
        f"<p>{len(odd)} of {len(values)} values not consistent with the arrivals:</p>\n"
        f'<table class="array">\n<thead><tr>{head}</tr></thead>\n<tbody>\n{body}\n</tbody>\n</table>'
    )


def _value_row(value: dict[str, str]) -> str:
    """One value's row: its cells in `_SHOWN` order (a position's with its distance and sd in
    km, array.csv's `shift` and `sd`), a contradicted one marked."""
    shown = dict(value)
    if value["field"] == "position":
        shown["estimated"] += f" ({value['shift']} km away)" if value.get("shift") else ""
        shown["sd"] += " km" if value["sd"] else ""
    num, contradicted = ' class="num"', ' class="contradicted"'
    cells = "".join(f"<td{num if name in _NUMERIC else ''}>{_esc(shown[name])}</td>" for name in _SHOWN)
    return f"<tr{contradicted if value['outcome'] == 'contradicted' else ''}>{cells}</tr>"
