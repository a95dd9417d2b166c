"""User-facing errors and recoverable-input warnings.

`InputError` is the one exception type for problems a user can fix (a bad file, a
wrong config key); the CLI turns it into a one-line message and exit code 2.
`Warnings` collects recoverable oddities (a dropped duplicate row, a TOA outside its
window) so that none of them is silent: they are printed on stderr and listed in
`run.json`. Each warning is a `Notice`: its one line of text and the kind of problem it
names (`WarningKind`), set where it is made, so that whoever triages floats (the mission
overview, the batch's findings) reads the kind, never the wording.
"""

from __future__ import annotations

import difflib
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any


class InputError(Exception):
    """A problem with user input; the message names the file, line or field.

    The message is always one line: line breaks inside it (e.g. from a quoted bad value
    or a parser's message) are replaced by spaces.
    """

    def __init__(self, message: str):
        text = " ".join(str(message).splitlines()).strip()
        super().__init__(text or "invalid input")


def nearest(name: str, choices: Iterable[str]) -> str:
    """' (did you mean X?)' for the closest of `choices`, or '' when none is close."""
    match = difflib.get_close_matches(name, list(choices), n=1, cutoff=0.6)
    return f" (did you mean {match[0]!r}?)" if match else ""


def nearest_id(name: str, ids: Iterable[str]) -> str:
    """`nearest` among the `ids` that carry the same numbers as `name`: float811 is another
    float than float767 or float812, never a typo of it."""
    numbers = [int(n) for n in re.findall(r"\d+", name)]
    return nearest(name, [i for i in ids if [int(n) for n in re.findall(r"\d+", i)] == numbers])


def listing(names: Sequence[str], most: int = 10) -> str:
    """Up to `most` names, comma-separated, and how many more."""
    more = f" and {len(names) - most} more" if len(names) > most else ""
    return ", ".join(names[:most]) + more


class WarningKind(StrEnum):
    """What a warning is about: the overview counts warnings by kind (run.json's `warning_kinds`)."""

    METADATA = "metadata"  # a table value the arrivals contradict or cannot decide
    END_FIX = "end fix"  # the end fix far from every particle
    SPLIT_TRACK = "split track"  # the two-filter smoother's filters held the float apart (`smoothing.split`)
    GAPS = "gaps"  # windows with no usable or active beacon
    OUTLIER_TOAS = "outlier TOAs"  # TOAs far from every particle's prediction
    LIKELIHOOD = "likelihood"  # a window's likelihood not finite
    CALIBRATION = "calibration"  # calibration not possible
    ARRIVAL_FILE = "arrival file"  # an oddity of the arrival file (duplicates, TOAs outside the window)
    MEMORY = "memory"  # a run the machine's memory may not hold
    OTHER = "other"


class Notice(str):
    """One warning line with its kind (`WarningKind`), set where it is made.

    A `str`: it prints, joins and is written to JSON as its text, so every place that shows
    warnings shows them unchanged; `kind_of` reads its kind wherever it travels (pickled
    across processes too)."""

    kind: WarningKind

    def __new__(cls, kind: WarningKind | str, text: str) -> Notice:
        notice = super().__new__(cls, text)
        notice.kind = WarningKind(kind)
        return notice

    def __getnewargs__(self) -> tuple[Any, ...]:  # type: ignore[override]
        return (self.kind, str(self))


def kind_of(message: str) -> WarningKind:
    """The kind of a warning: a `Notice`'s own, `OTHER` for plain text."""
    return message.kind if isinstance(message, Notice) else WarningKind.OTHER


@dataclass
class Warnings:
    """An ordered list of recoverable input problems, each a one-line `Notice`."""

    messages: list[str] = field(default_factory=list)

    def add(self, message: str, kind: WarningKind = WarningKind.ARRIVAL_FILE) -> None:
        """Append `message` as a warning of `kind` (an input oddity unless said)."""
        self.messages.append(message if isinstance(message, Notice) else Notice(kind, message))

    def __len__(self) -> int:
        return len(self.messages)
