"""Write a benchmark's results into its own section of a Markdown report (docs/validation.md).

A section runs from `<!-- NAME:start -->` to `<!-- NAME:end -->`; writing it replaces
only the text between its markers (or appends the section when the file lacks them), so
each benchmark script refreshes its own tables and leaves the others' alone. Every
section is stamped with the UTC date, the git commit (`+dirty` when the working tree has
changes) and the command line that produced it.
"""

from __future__ import annotations

import datetime
import os
import re
import shlex
import subprocess
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

import pandas as pd

REPO = Path(__file__).resolve().parents[1]


def git_commit(repo: Path = REPO) -> str:
    """The short commit of HEAD, with `+dirty` when tracked files have changes; `unknown` outside git."""
    try:
        head = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=repo, capture_output=True, text=True, check=True
        ).stdout.strip()
        changes = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"], cwd=repo, capture_output=True, text=True
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return head + ("+dirty" if changes else "")


LOCAL_PATH_OPTIONS = ("--out", "--csv")  # where this machine kept its files: not part of the result


def _without_local_paths(argv: list[str]) -> list[str]:
    """`argv` without the options that name scratch folders of the machine that ran it."""
    kept: list[str] = []
    skip = False
    for arg in argv:
        if skip:
            skip = False
        elif arg in LOCAL_PATH_OPTIONS:
            skip = True
        elif not arg.startswith(tuple(f"{o}=" for o in LOCAL_PATH_OPTIONS)):
            kept.append(arg)
    return kept


def stamp(argv: Sequence[str] | None = None) -> str:
    """One line: when, at which commit and with which command the section was written."""
    argv = _without_local_paths(list(sys.argv if argv is None else argv))
    script = Path(argv[0])
    if script.is_absolute() and script.is_relative_to(REPO):
        argv[0] = str(script.relative_to(REPO))
    today = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d")
    return f"_Written {today} at commit `{git_commit()}` by `python {shlex.join(argv)}`._"


def markdown_table(frame: pd.DataFrame, formats: dict[str, Callable[[object], str]] | None = None) -> str:
    """`frame` as a GitHub Markdown table; `formats` maps a column to its cell formatter
    (floats default to 3 decimals, missing values print empty)."""
    formats = formats or {}

    def cell(column: str, value: object) -> str:
        if value is None or (isinstance(value, float) and pd.isna(value)):
            return ""
        if column in formats:
            return formats[column](value)
        if isinstance(value, float):
            return f"{value:.3f}"
        return str(value)

    columns = [str(c) for c in frame.columns]
    numeric = [pd.api.types.is_numeric_dtype(frame[c]) for c in frame.columns]
    lines = ["| " + " | ".join(columns) + " |", "|" + "|".join("---:" if n else "---" for n in numeric) + "|"]
    for row in frame.itertuples(index=False):
        lines.append("| " + " | ".join(cell(c, v) for c, v in zip(columns, row, strict=True)) + " |")
    return "\n".join(lines)


def replace_section(text: str, name: str, body: str) -> str:
    """`text` with the section `name` holding `body` (replaced between its markers, or appended)."""
    start, end = f"<!-- {name}:start -->", f"<!-- {name}:end -->"
    block = f"{start}\n{body.strip()}\n{end}"
    pattern = re.compile(re.escape(start) + r".*?" + re.escape(end), re.DOTALL)
    if pattern.search(text):
        return pattern.sub(lambda _: block, text, count=1)
    return text.rstrip("\n") + ("\n\n" if text.strip() else "") + block + "\n"


def write_section(path: Path, name: str, body: str, argv: Sequence[str] | None = None) -> None:
    """Put `body`, under the stamp line, into section `name` of the Markdown file at `path`."""
    path = Path(path)
    text = path.read_text() if path.exists() else ""
    path.write_text(replace_section(text, name, f"{stamp(argv)}\n\n{body.strip()}"))
    print(f"wrote section {name!r} of {path}")


def machine() -> str:
    """The CPU model, core count and load average, for reading timings (`unknown CPU` where
    /proc/cpuinfo is absent)."""
    model = "unknown CPU"
    cpuinfo = Path("/proc/cpuinfo")
    if cpuinfo.exists():
        names = [
            line.split(":", 1)[1].strip() for line in cpuinfo.read_text().splitlines() if line.startswith("model name")
        ]
        model = names[0] if names else model
    load = os.getloadavg() if hasattr(os, "getloadavg") else None
    busy = "" if load is None else ", load average {:.2f} {:.2f} {:.2f} (1, 5, 15 min; this run included)".format(*load)
    return f"{model}, {os.cpu_count()} cores{busy}"
