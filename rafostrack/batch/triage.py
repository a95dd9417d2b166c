"""Which floats of the mission overview need a look: the rules, and the floats in the order shown.

A float needs a look (`LookRules`; each rule that applies is named in `reasons`) when it
failed, when its outputs cannot be read, when it has no window, when its arrivals contradict
a table value, when the end fix is far from every particle (a warning of kind `END_FIX`,
`errors.WarningKind`: the kind its warning was made with, whatever its wording), when its
two filters held it apart on some windows (`SPLIT_TRACK`, `smoothing.split`), or when a
share or the sd passes its limit: unsupported windows > 10%, ambiguous > 5%, recovered >
2%, 95th percentile of sd_km > 20 km, clutter > 50% of the TOAs. Order (`judged`): failed,
then needs a look (more reasons first), then ok; ties by mission and float id.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from ..errors import WarningKind
from ..plots.mission_map import NEEDS_LOOK, OK
from .overview_array import ArraySection
from .overview_rows import FloatRow
from .plan import FAILED

LOOK_ORDER = {FAILED: 0, NEEDS_LOOK: 1, OK: 2}


@dataclass(frozen=True)
class LookRules:
    """When a float needs a look (module docstring): the limits, each exceeded strictly."""

    unsupported_share_max: float = 0.10
    ambiguous_share_max: float = 0.05
    recovered_share_max: float = 0.02
    sd_km_p95_max: float = 20.0
    clutter_share_max: float = 0.50

    def describe(self) -> list[str]:
        """The rules as sentences, for the page."""
        return [
            "it failed in the batch, or its outputs cannot be read, or it has no window",
            "its arrivals contradict a value of floats.csv or beacons.csv (metadata checks)",
            "its end fix is far from every particle (an 'end fix' warning)",
            "its forward and backward filters held it apart on some windows (a 'split track' warning)",
            f"more than {self.unsupported_share_max:.0%} of its windows are unsupported (drift model only)",
            f"more than {self.ambiguous_share_max:.0%} of its windows are ambiguous (two positions)",
            f"more than {self.recovered_share_max:.0%} of its windows are recovered (the track was lost)",
            f"the 95th percentile of its sd_km is above {self.sd_km_p95_max:g} km",
            f"more than {self.clutter_share_max:.0%} of its TOAs are called clutter",
        ]

    def reasons(self, row: FloatRow) -> list[str]:
        """Why `row`'s float needs a look, one phrase per rule that applies (none: ok)."""
        if row.failed:
            return [f"failed: {row.failed}"]
        if row.unreadable:
            return [f"outputs unreadable: {row.unreadable}"]
        if not row.windows:
            return ["no window tracked"]
        reasons = []
        if row.contradicted:
            reasons.append("arrivals contradict " + "; ".join(what for what, _ in row.contradicted))
        if row.warning_kinds.get(WarningKind.END_FIX):
            reasons.append("end fix far from every particle")
        if row.warning_kinds.get(WarningKind.SPLIT_TRACK):
            reasons.append("its two filters held it apart (a 'split track' warning)")
        limits = (("unsupported", self.unsupported_share_max), ("ambiguous", self.ambiguous_share_max),
                  ("recovered", self.recovered_share_max))  # fmt: skip
        for status, limit in limits:
            share = row.shares.get(status, 0.0)
            if share > limit:
                reasons.append(f"{status} {share:.1%} of windows > {limit:.0%}")
        if row.sd_km_p95 is not None and row.sd_km_p95 > self.sd_km_p95_max:
            reasons.append(f"p95 sd {row.sd_km_p95:.1f} km > {self.sd_km_p95_max:g} km")
        if row.clutter_share is not None and row.clutter_share > self.clutter_share_max:
            reasons.append(f"clutter {row.clutter_share:.1%} of TOAs > {self.clutter_share_max:.0%}")
        return reasons


@dataclass(frozen=True)
class Overview:
    """The floats of an output tree, in the order shown (needing a look first)."""

    out: Path
    rows: list[FloatRow]
    not_tracked: int = 0  # listed in floats.csv but with no arrival file (or skipped otherwise)
    rules: LookRules = LookRules()
    findings: tuple[str, ...] = ()  # the mission's metadata findings, one line each (`findings.py`)
    arrays: tuple[ArraySection, ...] = ()  # each mission's array fit, when it has one (`overview_array.py`)

    def count(self, look: str) -> int:
        return sum(r.look == look for r in self.rows)


def judged(rows: Sequence[FloatRow], rules: LookRules) -> list[FloatRow]:
    """The rows with their look and reasons (`LookRules`), needing a look first (module docstring)."""
    out = []
    for row in rows:
        reasons = rules.reasons(row)
        look = FAILED if row.failed else NEEDS_LOOK if reasons else OK
        out.append(dataclasses.replace(row, look=look, reasons=tuple(reasons)))
    return sorted(out, key=lambda r: (LOOK_ORDER[r.look], -len(r.reasons), r.mission, r.float_id))
