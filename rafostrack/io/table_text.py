"""A table's own text with some cells changed: the same columns, rows, comments and line
ends (a column the table lacks is added, empty on the other rows)."""

from __future__ import annotations

import csv
import io
from collections.abc import Sequence


class NotTheRow(ValueError):
    """An edit's line is not the row of its id; `index`: which edit."""

    def __init__(self, index: int, line: int, row_id: str):
        super().__init__(f"line {line} is not the row of {row_id}")
        self.index = index


def with_cells(text: str, edits: Sequence[tuple[int, str, dict[str, str]]], id_column: str = "beacon_id") -> str:
    """`text` (a CSV table) with, per edit (line number, header = 1; the row's id; columns
    and cell texts), those cells replaced; `NotTheRow` when an edit's line is not the row of
    its id (the table changed since it was read)."""
    lines = text.splitlines(keepends=True)
    header = _fields(lines[0]) if lines else []
    for index, (line, row_id, cells) in enumerate(edits):
        at = line - 1
        row = _fields(lines[at]) if 0 < at < len(lines) else []
        if id_column not in header or header.index(id_column) >= len(row) or row[header.index(id_column)] != row_id:
            raise NotTheRow(index, line, row_id)
        for column, cell in cells.items():
            if column not in header:
                header.append(column)
            row += [""] * (len(header) - len(row))
            row[header.index(column)] = cell
        lines[at] = _line(row, lines[at])
    lines[0] = _line(header, lines[0])
    return "".join(lines)


def _fields(line: str) -> list[str]:
    return [cell.strip() for cell in next(csv.reader([line.rstrip("\r\n")]), [])]


def _line(fields: list[str], original: str) -> str:
    """`fields` as one CSV line with `original`'s line end."""
    out = io.StringIO()
    csv.writer(out, lineterminator="").writerow(fields)
    return out.getvalue() + original[len(original.rstrip("\r\n")) :]
