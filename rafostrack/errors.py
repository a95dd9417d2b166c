"""User-facing errors and recoverable-input warnings.

`InputError` is the one exception type for problems a user can fix (a bad file, a
wrong config key); the CLI turns it into a one-line message and exit code 2.
`Warnings` collects recoverable oddities (a dropped duplicate row, a TOA outside its
window) so that none of them is silent: they are printed on stderr and listed in
`run.json`.
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable
from dataclasses import dataclass, field


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


@dataclass
class Warnings:
    """An ordered list of recoverable input problems, each a one-line message."""

    messages: list[str] = field(default_factory=list)

    def add(self, message: str) -> None:
        self.messages.append(message)

    def __len__(self) -> int:
        return len(self.messages)
