"""Warnings carry their kind from where they are made (`errors.WarningKind`, `Notice`): one
producer of each kind at unit level, and a `Notice` through pickling (batch workers, forked
passes) and JSON (run.json) unchanged."""

from __future__ import annotations

import json
import pickle
from pathlib import Path
from types import SimpleNamespace

import numpy as np
from support import MODEL, read_small, write

from rafostrack.calibrate.metadata_checks import CONTRADICTED, ESTIMATED, MetadataCheck, warnings_of
from rafostrack.domain import Particles, PositionFix, Window
from rafostrack.errors import Notice, WarningKind, Warnings, kind_of
from rafostrack.filtering.filter import _finite_loglik
from rafostrack.io.csv_mission import read_beacons, read_floats
from rafostrack.likelihoods import LabelledArrivals, PositionFixLikelihood
from rafostrack.run.resources import memory_warning

BEACONS = "beacon_id,lat,lon,offset_s,start,end\nA,-58,-100,0,,\nB,-56,-95,600,2009-01-01,\n"
FLOATS = "float_id,launch_time,launch_lat,launch_lon,window_s,max_signals\nf1,2009-01-01T00:00:00Z,-57,-98,4000,3\n"


def _particles(lat: float = -57.0, lon: float = -98.0, n: int = 20) -> Particles:
    return Particles(np.full(n, lat), np.full(n, lon))


def test_a_notice_survives_pickling_and_is_its_text_in_json():
    notice = Notice(WarningKind.END_FIX, "f1: the end fix is 80.2 km from every particle")
    back = pickle.loads(pickle.dumps(notice))
    assert isinstance(back, Notice) and back == notice and back.kind == WarningKind.END_FIX
    assert pickle.loads(pickle.dumps((notice,)))[0].kind == WarningKind.END_FIX  # inside a PassResult's tuple too
    assert json.dumps({"warnings": [notice], "warning_kinds": [kind_of(notice)]}) == (
        '{"warnings": ["f1: the end fix is 80.2 km from every particle"], "warning_kinds": ["end fix"]}'
    )
    assert kind_of("a plain string") == WarningKind.OTHER


def test_warnings_add_an_arrival_file_oddity_unless_told_and_keep_a_notices_kind():
    warnings = Warnings()
    warnings.add("f1.csv: 2 duplicate row(s) dropped")
    warnings.add("f1.csv: 3 window(s) with no active beacon", kind=WarningKind.GAPS)
    warnings.add(Notice(WarningKind.MEMORY, "need about 9 GB"), kind=WarningKind.GAPS)
    assert [kind_of(m) for m in warnings.messages] == [WarningKind.ARRIVAL_FILE, WarningKind.GAPS, WarningKind.MEMORY]


def test_an_end_fix_far_from_every_particle_warns_of_kind_end_fix():
    fix = PositionFix(np.datetime64("2009-02-01T00:00:00"), -55.0, -98.0, 2.0)  # ~220 km north of the cloud
    evidence = PositionFixLikelihood("f1").evaluate(_particles(), fix)
    [warning] = evidence.warnings
    assert kind_of(warning) == WarningKind.END_FIX
    assert warning.startswith("f1: the end fix is ") and "its sd was widened to" in warning
    assert PositionFixLikelihood("f1").evaluate(_particles(-55.0), fix).warnings == ()  # near: no warning


def test_a_labelled_toa_far_from_every_prediction_warns_of_kind_outlier_toas(tmp_path: Path):
    beacons = read_beacons(write(tmp_path / "beacons.csv", BEACONS))
    info = read_floats(write(tmp_path / "floats.csv", FLOATS), MODEL)["f1"]
    window = Window(np.datetime64("2009-01-02T00:00:00"), np.array([3900.0]), beacon_id=("A",))  # A is ~150 s away
    [warning] = LabelledArrivals(beacons, info, MODEL).evaluate(_particles(), window).warnings
    assert kind_of(warning) == WarningKind.OUTLIER_TOAS
    assert "labelled A is" in warning and "sd from every particle's prediction" in warning


def test_a_likelihood_not_finite_warns_of_kind_likelihood():
    warnings: list[str] = []
    at = SimpleNamespace(time=np.datetime64("2009-01-02T00:00:00"))
    _finite_loglik(np.array([0.0, np.nan]), at, "f1", warnings)  # type: ignore[arg-type]
    _finite_loglik(np.array([np.nan, np.nan]), at, "f1", warnings)  # type: ignore[arg-type]
    assert [kind_of(w) for w in warnings] == [WarningKind.LIKELIHOOD] * 2
    assert warnings[0] == "f1: 2009-01-02T00:00:00Z: likelihood not finite for 1 particle(s); they were dropped"


def test_the_readers_warn_of_arrival_file_oddities_and_of_gaps(tmp_path: Path):
    beacons = "beacon_id,lat,lon,offset_s,start,end\nA,-58,-100,0,2009-01-03,\n"  # silent on the first day
    arrivals = "time,toa_s\n2009-01-02T00:00:00Z,100\n2009-01-02T00:00:00Z,100\n2009-01-03T00:00:00Z,200\n"
    _, warnings = read_small(tmp_path, arrivals=arrivals, beacons=beacons)
    kinds = {kind_of(m): m for m in warnings.messages}
    assert set(kinds) == {WarningKind.ARRIVAL_FILE, WarningKind.GAPS}
    assert "duplicate" in kinds[WarningKind.ARRIVAL_FILE] and "no active beacon" in kinds[WarningKind.GAPS]


def test_a_contradicted_or_empty_table_value_warns_of_kind_metadata():
    contradicted = MetadataCheck("beacons.csv", 4, "B3", "offset_s", 0.0, 30.5, 0.5, "s", CONTRADICTED)
    empty = MetadataCheck("floats.csv", 2, "f1", "clock_offset_end_s", None, -4.5, 0.5, "s", ESTIMATED)
    assert [kind_of(w) for w in warnings_of([contradicted, empty])] == [WarningKind.METADATA] * 2
    assert contradicted.warning() == (
        "beacons.csv: line 4: field 'offset_s' of B3: given 0 s; the arrivals support 30.5 s (sd 0.5 s); "
        "tracked with the arrivals' value"
    )


def test_a_run_the_memory_may_not_hold_warns_of_kind_memory():
    warning = memory_warning(10_000_000, 60, 1e9)
    assert warning is not None and kind_of(warning) == WarningKind.MEMORY and "need about" in warning
