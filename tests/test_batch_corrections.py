"""The beacon table the arrivals support (`rafostrack.batch.corrections`): which findings a
mission's floats decide, and the user's table with only those cells changed."""

from __future__ import annotations

import pytest

from rafostrack.batch.corrections import supported_table, to_correct
from rafostrack.batch.findings import Finding, Pooled

TABLE = "beacon_id,lat,lon,offset_s\r\nB1,-60.0,-70.0,300\r\nB2,-61.0,-72.0,900\r\n\r\nB3,-62.0,-74.0,1500\r\n"


def _finding(id_: str, line: int, field: str, supported, k: int, n: int, mission: str = "dimes", **more) -> Finding:
    floats = tuple(f"f{i}" for i in range(k))
    return Finding(mission, "/m/beacons.csv", line, id_, field, "s", 0.0, supported, floats, n, 0, True, **more)


def test_a_value_is_decided_by_most_floats_or_their_pool_and_never_on_the_wrong_source():
    """One mission per finding (a mission's table gets one value at a time)."""
    offset = _finding("B1", 2, "offset_s", 330.0, 3, 4, mission="a")  # 3 of 4 floats
    weak = _finding("B2", 3, "offset_s", 930.0, 1, 2, mission="b")  # 1 of 2: the other float saw nothing wrong
    pooled = _finding("B2", 3, "drift_s_per_day", None, 0, 3, mission="c", pooled=Pooled(0.03, 0.004, "contradicted"))
    unsure = _finding("B3", 5, "offset_s", 1530.0, 2, 2, mission="d", other_sources=("B1",))  # or B1's
    assert to_correct([offset, weak, pooled, unsure]) == [offset, pooled]


def test_one_value_per_mission_the_strongest_and_a_decided_position_explains_its_source_timing():
    """B1's position is decided on the floats' arrivals together, 8 sd away; B1's offset
    finding is its echo and never written; B2's drift pool is 4 sd away (2 floats of 3
    contradicting it come first, were there such a finding: `strength`). The position alone."""
    position = _finding("B1", 2, "position", 25.0, 0, 2, pooled=Pooled(25.0, 3.0, "contradicted", (-60.2, -69.8)))
    echo = _finding("B1", 2, "offset_s", 320.0, 2, 2, alternatives=("position",))
    drift = _finding("B2", 3, "drift_s_per_day", None, 0, 2, pooled=Pooled(0.02, 0.005, "contradicted"))
    assert to_correct([echo, drift, position]) == [position]
    most = _finding("B2", 3, "offset_s", 930.0, 2, 3)
    assert to_correct([echo, drift, position, most]) == [most]


def test_only_the_decided_cells_change_and_the_table_keeps_its_form():
    """B1 moved (pooled position), B3's offset (median of its floats) and drift (a column the
    table lacks, added): the other rows, the blank line and the CRLF line ends as they were."""
    position = _finding("B1", 2, "position", 25.0, 0, 2, pooled=Pooled(25.0, 3.0, "contradicted", (-60.2, -69.8)))
    offset = _finding("B3", 5, "offset_s", 1530.25, 2, 2)
    drift = _finding("B3", 5, "drift_s_per_day", 0.035, 2, 2)
    assert supported_table(TABLE, [position, offset, drift]) == (
        "beacon_id,lat,lon,offset_s,drift_s_per_day\r\n"
        "B1,-60.2000,-69.8000,300\r\n"
        "B2,-61.0,-72.0,900\r\n"
        "\r\n"
        "B3,-62.0,-74.0,1530.250,0.03500\r\n"
    )


def test_a_table_changed_since_the_floats_were_tracked_is_not_written():
    with pytest.raises(ValueError, match="line 3 is not the row of source B3"):
        supported_table(TABLE, [_finding("B3", 3, "offset_s", 1530.0, 2, 2)])
