"""Strict CSV reading: one-line errors naming the file, line and field.

`read_csv_table` checks the encoding, the header (required, optional and unknown columns,
with the nearest name suggested) and the row structure, then returns stripped text
columns indexed by each row's line number in the file (as a text editor counts them,
header = line 1). The `parse_*` and `require_*` helpers turn columns into checked arrays.
Times are ISO-8601; a time without a zone is taken as UTC; all times are held as UTC
`numpy.datetime64[ns]`.
"""

from __future__ import annotations

import codecs
import csv
import warnings as pywarnings
from pathlib import Path
from typing import NoReturn

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from ..domain import NaT
from ..errors import InputError, nearest

_EXTRA = "\x00extra"  # sentinel column: a row with more fields than the header fills it
_CHUNK = 1 << 20  # bytes per chunk when checking the encoding
_ROWS_PER_CHUNK = 100_000  # rows per chunk when parsing
# Times must fit numpy's datetime64[ns]: years 1678-2261.
_TIME_MIN = pd.Timestamp("1678-01-01", tz="UTC")
_TIME_MAX = pd.Timestamp("2261-12-31", tz="UTC")


def time_text(t: np.datetime64) -> str:
    return f"{np.datetime_as_string(t, 's')}Z"


def _line_breaks(data: bytes) -> int:
    return data.count(b"\n") + data.count(b"\r") - data.count(b"\r\n")


def _check_utf8(path: Path) -> bool:
    """Decode the file in chunks (bounded memory); a bad byte is an error naming its line.
    Returns whether the file holds a quote character (only then can a field hold a line break)."""
    decoder = codecs.getincrementaldecoder("utf-8-sig")(errors="strict")
    lines_before = 0
    quoted = False
    with open(path, "rb") as fh:
        while True:
            chunk = fh.read(_CHUNK)
            pending = len(decoder.getstate()[0])
            try:
                decoder.decode(chunk, final=not chunk)
            except UnicodeDecodeError as exc:
                line = lines_before + _line_breaks(chunk[: max(exc.start - pending, 0)]) + 1
                bad = exc.object[exc.start : exc.start + 1]
                raise InputError(
                    f"{path}: line {line}: not UTF-8 text (byte 0x{bad.hex() or '??'}); "
                    "expected a UTF-8 (or ASCII) CSV file"
                ) from None
            if not chunk:
                return quoted
            lines_before += _line_breaks(chunk)
            quoted = quoted or b'"' in chunk


def _read_header(path: Path, required: tuple[str, ...]) -> tuple[list[str], int]:
    """The header's column names and the number of lines it (and blank lines before it) took."""
    try:
        with open(path, encoding="utf-8-sig", newline="") as fh:
            reader = csv.reader(fh, skipinitialspace=True)
            for fields in reader:
                if any(f.strip() for f in fields):
                    return [f.strip() for f in fields], reader.line_num
    except csv.Error as exc:
        raise InputError(f"{path}: line 1: cannot parse the header as CSV ({exc})") from None
    raise InputError(f"{path}: file is empty (expected a header line: {', '.join(required)})")


def _check_header(path: Path, header: list[str], line: int, required: tuple[str, ...], optional: tuple[str, ...]):
    known = (*required, *optional)
    where = f"{path}: line {line}"
    if len(header) == 1:
        for sep, name in ((";", "';'"), ("\t", "tabs"), ("|", "'|'")):
            if sep in header[0]:
                raise InputError(
                    f"{where}: columns are separated by {name}; expected ',' (comma-separated CSV with columns "
                    f"{', '.join(required)})"
                )
    for i, col in enumerate(header):
        if "\n" in col or "\r" in col:
            raise InputError(f"{where}: column {i + 1} name contains a line break (an unclosed quote?)")
        if not col:
            raise InputError(
                f"{where}: column {i + 1} has no name (a trailing comma?); expected only the columns {', '.join(known)}"
            )
    unknown = [c for c in header if c not in known]
    for col in required:
        if col not in header:
            typo = nearest(col, unknown).removeprefix(" (did you mean ").removesuffix("?)")
            hint = f" (the header has {typo}: did you mean {col!r}?)" if typo else ""
            raise InputError(f"{where}: missing required column {col!r}{hint}")
    for col in header:
        if col not in known:
            hint = nearest(col, known) or f" (expected only {', '.join(known)})"
            raise InputError(f"{where}: unknown column {col!r}{hint}")
    seen: set[str] = set()
    for col in header:
        if col in seen:
            raise InputError(f"{where}: column {col!r} appears twice; expected each column once")
        seen.add(col)


def _raise_long_row(path: Path, header: list[str], header_lines: int) -> None:
    """Raise for the first row with more (non-empty) fields than the header; a slow pass,
    only taken when pandas has met such a row. Returns if every extra field is empty."""
    n = len(header)
    with open(path, encoding="utf-8-sig", newline="") as fh:
        reader = csv.reader(fh, skipinitialspace=True)
        start = 1
        try:
            for fields in reader:
                if reader.line_num > header_lines and len(fields) > n and any(f.strip() for f in fields[n:]):
                    raise InputError(
                        f"{path}: line {start}: {len(fields)} fields; expected {n} "
                        f"(as many as the header: {', '.join(header)})"
                    )
                start = reader.line_num + 1
        except csv.Error as exc:
            raise InputError(f"{path}: line {start}: cannot parse as CSV ({exc})") from None


def read_csv_table(path: Path, required: tuple[str, ...], optional: tuple[str, ...]) -> pd.DataFrame:
    """Read a CSV as stripped text columns after checking its header.

    The frame's index holds each row's line number in the file (as a text editor counts
    them, header = line 1); blank lines are skipped. Fewer fields than the header means
    the missing trailing fields are empty; more fields is an error.
    """
    path = Path(path)
    quoted, header, header_lines = _checked_header(path, required, optional)
    frame = _parse_rows(path, header, header_lines)
    frame = _checked_rows(path, frame, header, quoted)
    frame.attrs["first_data_line"] = header_lines + 1
    return frame


def require_file(path: Path, expected: str) -> None:
    """InputError unless `path` is a regular file; `expected` says what it should be.

    A path that does not exist is "file not found", a directory "is a directory" (not the
    "file not found" of a path that is there), anything else "not a regular file".
    """
    if path.is_dir():
        raise InputError(f"{path}: is a directory, not a file ({expected})")
    if not path.exists():
        raise InputError(f"{path}: file not found ({expected})")
    if not path.is_file():
        raise InputError(f"{path}: not a regular file ({expected})")


def _checked_header(path: Path, required: tuple[str, ...], optional: tuple[str, ...]) -> tuple[bool, list[str], int]:
    """The file is a readable UTF-8 file with a valid header: whether it has quotes, the
    header's columns and how many lines the header takes."""
    require_file(path, f"expected a CSV file with columns {', '.join(required)}")
    try:
        quoted = _check_utf8(path)
        header, header_lines = _read_header(path, required)
    except OSError as exc:
        raise InputError(f"{path}: cannot read: {exc.strerror or exc}") from None
    _check_header(path, header, header_lines, required, optional)
    return quoted, header, header_lines


def _parse_rows(path: Path, header: list[str], header_lines: int) -> pd.DataFrame:
    """The rows after the header as text, the header's columns and `_EXTRA` (fields beyond
    the header's), indexed by line; a parse failure or a row too long is an InputError."""
    try:
        with pywarnings.catch_warnings(record=True) as caught:
            # pandas only warns (and drops the extra fields) when a row has more fields than
            # the names given; make that an error below.
            pywarnings.simplefilter("always", pd.errors.ParserWarning)
            # In chunks: the parser's temporary Python strings then stay bounded.
            with pd.read_csv(
                path,
                header=None,
                names=[*header, _EXTRA],
                skiprows=header_lines,
                dtype=str,
                keep_default_na=False,
                na_filter=False,
                encoding="utf-8-sig",
                skipinitialspace=True,
                index_col=False,
                skip_blank_lines=False,
                engine="c",
                chunksize=_ROWS_PER_CHUNK,
            ) as chunks:
                parts = list(chunks)
        frame = pd.concat(parts, ignore_index=True) if parts else None
    except pd.errors.EmptyDataError:
        frame = None
    except pd.errors.ParserError as exc:
        _raise_parser_error(path, header, header_lines, exc)
    except (ValueError, UnicodeError, OSError, OverflowError) as exc:
        reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise InputError(f"{path}: cannot parse as CSV: {reason}") from None
    if any(issubclass(w.category, pd.errors.ParserWarning) for w in caught):
        _raise_long_row(path, header, header_lines)
    if frame is None:
        frame = pd.DataFrame({c: pd.Series([], dtype=str) for c in [*header, _EXTRA]})
    frame.index = pd.RangeIndex(header_lines + 1, header_lines + 1 + len(frame))
    return frame


def _raise_parser_error(path: Path, header: list[str], header_lines: int, exc: pd.errors.ParserError) -> NoReturn:
    """The InputError for pandas' parser error: a row too long (found by `_raise_long_row`),
    an unclosed quote, or pandas' own first line of explanation."""
    text = str(exc).strip()
    if "Expected" in text and "fields" in text:
        _raise_long_row(path, header, header_lines)
        raise InputError(f"{path}: a row has more fields than the header; expected {len(header)}") from None
    reason = text.splitlines()[0] if text else type(exc).__name__
    if "EOF inside string" in reason:
        reason = 'a quote (") is never closed'
    raise InputError(f"{path}: cannot parse as CSV: {reason}") from None


def _checked_rows(path: Path, frame: pd.DataFrame, header: list[str], quoted: bool) -> pd.DataFrame:
    """The rows stripped, without `_EXTRA` and blank rows; InputError for a line break in a
    (quoted) field or a non-empty field beyond the header's."""
    broken = np.zeros(len(frame), dtype=bool)
    for col in frame.columns if quoted else ():
        broken |= (
            frame[col].str.contains("\n", regex=False).to_numpy()
            | frame[col].str.contains("\r", regex=False).to_numpy()
        )
    if broken.any():
        line = int(frame.index[np.argmax(broken)])
        raise InputError(f"{path}: line {line}: a field contains a line break (an unclosed quote?)")
    frame = frame.apply(lambda c: c.str.strip())
    extra = (frame[_EXTRA] != "").to_numpy()
    if extra.any():
        line = int(frame.index[np.argmax(extra)])
        raise InputError(
            f"{path}: line {line}: more fields than the header; expected {len(header)} ({', '.join(header)})"
        )
    frame = frame.drop(columns=_EXTRA)
    blank = np.ones(len(frame), dtype=bool)
    for col in frame.columns:
        blank &= (frame[col] == "").to_numpy()
    if blank.any():
        frame = frame[~blank]
    return frame


def line_of(frame: pd.DataFrame, row: int) -> int:
    """The file line of positional row `row` (see `read_csv_table`)."""
    return int(frame.index[row])


def _looks_numeric(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def parse_float_column(
    path: Path,
    frame: pd.DataFrame,
    col: str,
    *,
    default: float | None = None,
    lo: float = -np.inf,
    hi: float = np.inf,
    expect: str | None = None,
) -> NDArray[np.float64]:
    """Finite numbers in [lo, hi] (`expect` describes the range in messages); an empty cell
    takes `default` (NaN if None)."""
    if col not in frame.columns:
        return np.full(len(frame), np.nan if default is None else default)
    text = frame[col]
    empty = (text == "").to_numpy()
    values = pd.to_numeric(text.where(~empty, None), errors="coerce")
    values = np.asarray(values, dtype=float).copy()
    if expect is None:
        expect = f"in [{lo:g}, {hi:g}]" if np.isfinite(lo) and np.isfinite(hi) else ""
        expect = expect or (f">= {lo:g}" if np.isfinite(lo) else f"<= {hi:g}" if np.isfinite(hi) else "")
    bad = ~empty & ~np.isfinite(values)
    if bad.any():
        row = int(np.argmax(bad))
        got = text.iloc[row]
        where = f"{path}: line {line_of(frame, row)}: field {col!r}"
        if _looks_numeric(got):
            raise InputError(f"{where}: expected a finite number{' ' + expect if expect else ''}, got {got!r}")
        raise InputError(f"{where}: expected a number, got {got!r}{' (a value ' + expect + ')' if expect else ''}")
    if default is not None:
        values[empty] = default
    out = ~empty & ~((values >= lo) & (values <= hi))
    if out.any():
        row = int(np.argmax(out))
        raise InputError(
            f"{path}: line {line_of(frame, row)}: field {col!r}: expected a finite value {expect}, "
            f"got {text.iloc[row]!r}"
        )
    return values


def parse_time_column(path: Path, frame: pd.DataFrame, col: str) -> NDArray[np.datetime64]:
    """ISO-8601 times as UTC datetime64[ns]; empty cells are NaT; times without a zone are UTC."""
    out = np.full(len(frame), NaT)
    if col not in frame.columns:
        return out
    text = frame[col]
    present = (text != "").to_numpy()
    if present.any():
        # Arrival files repeat each window's time for every TOA: parse each distinct text once.
        codes, uniques = pd.factorize(text[present])
        parsed = pd.to_datetime(pd.Series(uniques, dtype=str), utc=True, format="ISO8601", errors="coerce")
        ok = (parsed.notna() & (parsed >= _TIME_MIN) & (parsed <= _TIME_MAX)).to_numpy()
        if not ok.all():
            row = int(np.flatnonzero(present)[np.argmax(~ok[codes])])
            raise InputError(
                f"{path}: line {line_of(frame, row)}: field {col!r}: expected an ISO-8601 time "
                f"(e.g. 2009-01-23T00:00:00Z, years 1678-2261), got {text.iloc[row]!r}"
            )
        out[present] = parsed.dt.tz_convert(None).dt.as_unit("ns").to_numpy(dtype="datetime64[ns]")[codes]
    return out


def require_present(path: Path, frame: pd.DataFrame, col: str, expect: str = "a value") -> None:
    empty = (frame[col] == "").to_numpy()
    if empty.any():
        line = line_of(frame, int(np.argmax(empty)))
        raise InputError(f"{path}: line {line}: field {col!r} is empty; expected {expect}")


def first_duplicate(path: Path, frame: pd.DataFrame, col: str) -> None:
    dup = frame[col].duplicated(keep="first").to_numpy()
    if dup.any():
        row = int(np.argmax(dup))
        value = frame[col].iloc[row]
        first = int(np.argmax((frame[col] == value).to_numpy()))
        raise InputError(
            f"{path}: line {line_of(frame, row)}: duplicate {col} {value!r} (first on line {line_of(frame, first)}); "
            f"field {col!r}: expected each id once"
        )


def header_only(path: Path, frame: pd.DataFrame, what: str) -> InputError:
    line = frame.attrs.get("first_data_line", 2)
    return InputError(f"{path}: line {line}: no rows after the header (header only); expected at least one {what}")
