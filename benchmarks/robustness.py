"""Robustness on the stress scenario: floats the tracker's own model did not make.

Simulates missions with `rafostrack.sim.stress` (two real arrays, DIMES and Weddell; clutter
rates 1, 2, 3; 240 days; eddying drift around a meandering jet, recording gaps,
range-faded and Markov-fading detection, multipath, source outages, clock wander, a
sound-speed mismatch, heavy-tailed noise, clutter bursts), writes them as mission
directories, and tracks every float as a user would, from the files
(`run.one_float.track_float`) with the DEFAULT settings, and with the true labels
(`--likelihood labeled`, the reference a hand-labelling analyst would reach), each once per
filter seed (`[filter] seed`; `FILTER_SEEDS`, 0 1 2 3, unless `--filter-seeds`). A user
tracks a float once, under one seed, so the worst seed is the one that counts. Prints, per
filter seed and float: RMSE, p95 and max error (km), labels right, the labels an oracle gets
at the true track with the true nuisances (`oracle_labels`: how ambiguous the float's
arrivals are), 95%-ellipse coverage, the status counts, the median ESS, the true-label
filter's RMSE, p95, the ratio and its coverage, the run time, and the confidently wrong
answers: windows more than 30 km off with an sd_km under half the error (`confident_wrong`,
and the true-label filter's), labels given with probability >= 0.99 that are wrong
(`wrong_p99`) beside the number such probabilities predict (`expected_p99`); then that
seed's robustness targets, each relative to its reference on the same floats (`targets`: p95
<= max(15 km, 1.2x the true-label filter's), RMSE <= max(5 km, 1.2x), coverage in [88%, 99%]
wherever the true-label filter's is, labels within 1 point of the oracle's, no more
confidently wrong windows than the true-label filter), with the floats failing each and
those on which the reference fails the same test, and the reliability of the label
probabilities over all floats (`evaluate.label_reliability`).

The verdict is judged under every filter seed (`worst_seed_targets`): a target holds only if
it holds under each seed, and per target it lists the floats that fail it under ANY seed,
each with the seeds it fails under (and so for the reference's own failures). The true-label
filter is tracked with the same filter seed as the default run, so each seed's run is judged
against that seed's true-label filter (like with like); the oracle's labels take no random
draws and are the same for every seed. Then, per float, how the seeds differ (`seed_spread`,
`seed_figures`): the RMS distance of the seeds' tracks from their mean (the Monte Carlo error
of the whole method, which the reported sd_km does not include) beside the median sd_km, the
smallest and largest RMSE over the seeds, the most confidently wrong windows under any seed,
and `rmse_unstable` where the seeds' RMSEs differ by more than max(2 km, 50% of the
smallest). `--filter-seeds 0` tracks with one seed only (0 is `[filter] seed` of the default
configuration; a `--config` layer's seed is overridden either way); the verdict is then that
seed's, and there is no spread.

The defaults were tuned on the missions of seed 2026; other `--seed`s are missions they have
not seen. Several seeds (`--seed 2026 2027 2028`) run one after the other and end with a
table: per target, pass/FAIL (under every filter seed) and the floats beyond it on each
scenario seed, beside the reference's own. The default run tracks every float 8 times (4
filter seeds, default and true labels): four times the work of one seed.

    python benchmarks/robustness.py [--floats 24] [--days 240] [--seed 2026 ...] [--workers 2]
                                    [--out DIR] [--config FILE] [--only ID ...] [--csv FILE]
                                    [--filter-seeds 0 1 2 3] [--knob NAME=VALUE ...]
                                    [--report docs/validation.md]

`--knob NAME=VALUE` sets a number knob of the stress generator (`StressConfig`) for every
mission, e.g. `--knob clutter_taper=0.8` to break an assumption of the tracker's model.

A single run's per-float figures move with the filter's random path (docs/decisions.md):
a float right under three seeds can be confidently wrong under a fourth, which a verdict
on one seed, or on the floats failing with every seed, would call a pass.

`--report FILE` also writes the targets under every filter seed, the seeds' spread per
float, and per seed the table, that seed's targets and the label reliability into the
`robustness` section of that Markdown file (`benchmarks/report.py`).

Metadata faults: `--faults SET [SET ...]`, each SET `all` (every kind at once), `each` (one
mission set per kind; kinds in `rafostrack.sim.faults.FAULT_KINDS`) or `KIND[,KIND...]`
simulates the missions with true clocks that drift (end offsets uniform in
`CLOCK_END_OFFSET_S`) and a share of floats that never surfaced (`--never-surfaced`, default
`NEVER_SURFACED_SHARE` here, 0 without --faults), tracks every float with the correct tables
(the reference: the run above, with the configured `[filter] seed` only: `--filter-seeds`
is refused) and with the faulted ones, and prints per float the faulted
run's RMSE, p95, coverage and confidently wrong windows beside the correct tables' (`ok_*`),
the faults named in run.json's "metadata_checks" (a missing key names nothing; of a source's
faults, those the float's arrivals can show, `faults.observable`, while `unobservable`
counts the others) and the false alarms (contradicted values that were right; those of the
correct tables' run too), then the targets, judged against the correct tables' run: p95 <=
max(15 km, 1.2x), RMSE <= max(5 km, 1.2x), coverage in [88%, 99%] wherever the correct
tables' is, no more confidently wrong windows, every fault the float's arrivals show named
(on the float's own checks, and with what a batch finds on the mission's floats together:
`batch.findings` pools a source's offset and drift), at most one false alarm per 100
floats. The correct tables' run is scored against the stress targets above too (under that
one seed).
`--report` then writes the `robustness-faults` section.

    python benchmarks/robustness.py --faults each [all] [--floats 24] [--days 240] [--never-surfaced 0.1] ...
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import multiprocessing
import tempfile
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import pandas as pd
from report import markdown_table, write_section

from rafostrack.batch.findings import Finding, mission_findings, parse_checks
from rafostrack.batch.workers import single_threaded_math
from rafostrack.config import with_overrides
from rafostrack.domain import FloatInfo, Particles
from rafostrack.likelihoods import arrivals_from_config
from rafostrack.model.geodesy import local_offsets_km
from rafostrack.run.one_float import LoadedFloat, TrackInputs, load_float, track_float
from rafostrack.sim.evaluate import (
    confidently_wrong,
    inside_ellipse,
    label_reliability,
    label_scores,
    position_errors_km,
)
from rafostrack.sim.faults import (
    FAULT_KINDS,
    InjectedFault,
    check_kinds,
    false_alarms,
    observable,
    read_faults,
    unnamed_faults,
)
from rafostrack.sim.stress import (
    DAY_NS,
    FAULT_STREAM,
    StressConfig,
    StressMission,
    simulate_stress,
    substream,
    with_faults,
    write_stress_mission,
)
from rafostrack.summaries.posterior import ELLIPSE_95_SCALE

CLUTTER_RATES = (1.0, 2.0, 3.0)
GEOMETRIES = ("dimes", "weddell")
TRUE_LABELS = {"filter": {"likelihood": "labeled"}}  # the reference filter's one difference
CONFIDENT_PROB = 0.99  # a label given with at least this probability is a confident one
COVERAGE_RANGE = (0.88, 0.99)  # the target for the 95% ellipses' coverage of the truth
CLOCK_END_OFFSET_S = (-40.0, 40.0)  # --faults: the true float clocks' end offsets (DIMES: -66..+45 s)
NEVER_SURFACED_SHARE = 0.1  # --faults: the share of floats that never surfaced, unless --never-surfaced
FALSE_ALARMS_PER_FLOAT = 0.01  # --faults: at most one false alarm per 100 floats
FILTER_SEEDS = (0, 1, 2, 3)  # the [filter] seeds every float is tracked with, unless --filter-seeds
SEED_RMSE_GAP = (2.0, 0.5)  # seeds' RMSEs differ: by more than max(km, share of the smallest)
OFF_WINDOW_KM = 15.0  # a window of the worst seed this much farther off than the best seed's
FLAGGED = ("ambiguous", "recovered", "unsupported")  # statuses saying the track is not sure there


@dataclasses.dataclass(frozen=True)
class Simulated:
    """One mission of the benchmark: its directory name, the mission, its configuration and
    the generator it was drawn from (whose seed the faults' generator derives from)."""

    name: str
    mission: StressMission
    cfg: StressConfig
    rng: np.random.Generator


def simulate_missions(n_floats: int, days: int, seed: int, knobs: dict[str, Any] | None = None) -> list[Simulated]:
    """n_floats floats, split over the geometries and clutter rates (stress `knobs` on top)."""
    groups = [(g, c) for g in GEOMETRIES for c in CLUTTER_RATES]
    per_group = [n_floats // len(groups) + (k < n_floats % len(groups)) for k in range(len(groups))]
    missions = []
    for k, ((geometry, clutter), n) in enumerate(zip(groups, per_group, strict=True)):
        if n == 0:
            continue
        cfg = StressConfig(days=days, clutter_rate=clutter, **(knobs or {}))
        rng = np.random.default_rng([seed, k])
        mission = simulate_stress(geometry, n, rng, cfg, prefix=f"{geometry[0]}{int(clutter)}f")
        missions.append(Simulated(f"{geometry}_clutter{int(clutter)}", mission, cfg, rng))
    return missions


def write_missions(root: Path, missions: list[Simulated]) -> list[Path]:
    """The missions' directories under `root`; their float files."""
    files = []
    for sim in missions:
        write_stress_mission(sim.mission, root / sim.name)
        files += [root / sim.name / f"{f.info.float_id}.csv" for f in sim.mission.floats]
    return files


def make_missions(root: Path, n_floats: int, days: int, seed: int, knobs: dict[str, Any] | None = None) -> list[Path]:
    """n_floats floats, split over the geometries and clutter rates; their float files."""
    return write_missions(root, simulate_missions(n_floats, days, seed, knobs))


def oracle_labels(loaded: LoadedFloat, events: dict[str, Any], truth: pd.DataFrame) -> float:
    """Labels right when each window is labelled at the TRUE position with the TRUE nuisances
    (per-source sound speed, drift error and detection, the float clock's wander and, where
    the mission records it, its true drift, TOA sd, clutter rate, multipath split evenly
    between replaced and echoed arrivals): the ceiling a labeller reaches when the track is
    known. It is not the Bayes rate exactly (the simulator's delays are lognormal, its noise
    heavy-tailed, its detection fades in bad propagation regimes; the model's are not), but
    clutter that lands within a few seconds of a source's predicted arrival is as ambiguous
    here as for the tracker. The rest of the model (e.g. the multipath delay law) is the run's
    configuration, `--config` layers included."""
    b, info, per = loaded.problem.beacons, _true_linear_clock(loaded.problem.info, events, truth), events["beacons"]
    ids = list(b.beacon_id)
    beacons = dataclasses.replace(
        b,
        drift_s_per_day=b.drift_s_per_day + np.array([per[i]["drift_error_s_per_day"] for i in ids]),
        sound_speed_m_s=np.array([per[i]["sound_speed_m_s"] for i in ids]),
        p_detect=np.array([per[i]["p_detect"] for i in ids]),
        detection_range_km=np.array([per[i]["detection_range_km"] for i in ids]),
    )
    days = np.arange(int((info.end_time - info.launch_time) / DAY_NS) + 1)
    frac, wander = days / days[-1], events["clock_wander"]
    clock_s = events["clock_wander_s"] * np.sin(2 * np.pi * days / wander["period_days"] + wander["phase"])
    info = dataclasses.replace(info, clock_residual=(info.launch_time + DAY_NS * days, clock_s * 4 * frac * (1 - frac)))
    half = events["multipath_fraction"] / 2
    model = {"toa_sigma_s": events["toa_sd_s"], "clutter_rate": events["clutter_rate"], "multipath_delay_s": 22.0}
    config = with_overrides(
        loaded.problem.config,
        filter={"likelihood": "ranked"},
        model={**model, "multipath_fraction": half, "echo_fraction": half},
    )
    arrivals = arrivals_from_config(beacons, info, config)
    at = truth.set_index("time")
    right, total = 0, 0
    for window in loaded.record.windows:
        if window.n_signals == 0 or window.time not in at.index:
            continue
        row = at.loc[window.time]
        particle = Particles(np.array([row["lat"]]), np.array([row["lon"]]), np.zeros((1, 2)))
        probs, index = arrivals.label_probs(particle, np.ones(1), window)
        names = [*beacons.beacon_id[index], None]
        best = np.argmax(np.vstack([probs, 1.0 - probs.sum(axis=0, keepdims=True)]), axis=0)
        true_ids = window.beacon_id
        assert true_ids is not None  # the record was loaded with its true labels
        right += sum(names[k] == (t if isinstance(t, str) else None) for k, t in zip(best, true_ids, strict=True))
        total += window.n_signals
    return right / total if total else float("nan")


def _true_linear_clock(info: FloatInfo, events: dict[str, Any], truth: pd.DataFrame) -> FloatInfo:
    """`info` with the true clock's offsets from launch to the truth's last time, where the
    mission records them (drifting clocks, floats that never surfaced); else `info`."""
    if "true_clock_offset_s" not in events:
        return info
    start_s, end_s = events["true_clock_offset_s"]
    end = truth["time"].iloc[-1].to_datetime64().astype("datetime64[ns]")
    return dataclasses.replace(info, end_time=end, clock_offset_start_s=start_s, clock_offset_end_s=end_s)


def read_truth(float_file: Path) -> tuple[pd.DataFrame, dict[str, Any]]:
    """A float's true track (naive UTC times) and its events (`truth/<float_id>.csv`, `.json`)."""
    truth = pd.read_csv(float_file.parent / "truth" / f"{float_file.stem}.csv", parse_dates=["time"])
    truth["time"] = truth["time"].dt.tz_localize(None)
    return truth, json.loads((float_file.parent / "truth" / f"{float_file.stem}.json").read_text())


def position_figures(track: pd.DataFrame, truth: pd.DataFrame) -> dict[str, float]:
    """A track's RMSE, p95 and max error (km), 95%-ellipse coverage and confidently wrong windows."""
    err = position_errors_km(track, truth)
    return {
        "rmse_km": float(np.sqrt(np.mean(err**2))),
        "p95_km": float(np.percentile(err, 95)),
        "max_km": float(err.max()),
        "cover95": float(np.mean(inside_ellipse(track, truth, ELLIPSE_95_SCALE))),
        "confident_wrong": int(confidently_wrong(err, track["sd_km"].to_numpy()).sum()),
    }


def score(task: tuple[Path, Path, tuple[Path, ...], int | None]) -> tuple[dict[str, Any], pd.DataFrame]:
    """Track one float by default and with its true labels (with the filter seed, when
    given); score both against the truth. Returns the float's row and its labels' scores
    (`evaluate.label_scores`)."""
    float_file, out_root, config_files, seed = task
    seeded: dict[str, Any] = {}
    if seed is not None:
        seeded = {"seed": seed}
        out_root = out_root / f"seed{seed}"
        out_root.mkdir(exist_ok=True)
    truth, events = read_truth(float_file)
    started = time.perf_counter()
    result = track_float(
        TrackInputs(float_file, config_files=config_files, overrides={"filter": seeded}),
        out_root / "default",
        plots=False,
    )
    seconds = time.perf_counter() - started
    ref_overrides = {"filter": {**TRUE_LABELS["filter"], **seeded}}
    ref = track_float(
        TrackInputs(float_file, config_files=config_files, overrides=ref_overrides), out_root / "labelled", plots=False
    )
    track = result.output.track
    # the true labels, and the configuration the oracle starts from: the run's, so that a
    # model being tried (`--config`) is tried by the oracle too
    labelled = load_float(TrackInputs(float_file, config_files=config_files, overrides=TRUE_LABELS))
    ref_track = ref.output.track
    err = position_errors_km(track, truth)
    ours, theirs = position_figures(track, truth), position_figures(ref_track, truth)
    status = track["status"].value_counts().to_dict() if "status" in track else {}
    labels = label_scores(result.output.labels, labelled.record)
    confident = labels[labels["prob"] >= CONFIDENT_PROB]
    row = {
        "float": float_file.stem,
        "filter_seed": seed,
        "geometry": events["geometry"],
        "clutter": events["clutter_rate"],
        "rmse_km": ours["rmse_km"],
        "p95_km": ours["p95_km"],
        "max_km": ours["max_km"],
        "labels": float(labels["right"].mean()),
        "labels_oracle": oracle_labels(labelled, events, truth),
        "cover95": ours["cover95"],
        "ess_med": float(np.median(result.output.counts.filter_ess)),
        "ref_rmse_km": theirs["rmse_km"],
        "ref_p95_km": theirs["p95_km"],
        "ref_cover95": theirs["cover95"],
        "seconds": seconds,
        "windows": len(track),
        "confident_wrong": ours["confident_wrong"],
        "ref_confident_wrong": theirs["confident_wrong"],
        "wrong_p99": int((~confident["right"]).sum()),
        "expected_p99": float((1.0 - confident["prob"]).sum()),
        **{f"n_{k}": int(v) for k, v in status.items()},
        "n_ambiguous": int(track["ambiguous"].sum()),
    }
    row["ratio"] = row["rmse_km"] / row["ref_rmse_km"]
    errors = pd.DataFrame({"time": track["time"], "error_km": err, "sd_km": track["sd_km"]})
    errors.to_csv(out_root / f"errors_{float_file.stem}.csv", index=False)
    return row, labels.assign(filter_seed=seed)


def _of_seed(frame: pd.DataFrame, seed: int | None) -> pd.DataFrame:
    """The rows of `frame` from the runs with `[filter] seed` = `seed` (None: the configured seed)."""
    return frame[frame["filter_seed"].isna()] if seed is None else frame[frame["filter_seed"] == seed]


def seed_spread(out_root: Path, seeds: list[int], floats: list[str]) -> pd.DataFrame:
    """Per float, how far the default tracks of the filter `seeds` lie apart: the RMS
    distance (km) of each seed's positions from their mean over the seeds, sqrt(n / (n - 1))
    x the sample's (so that it estimates one run's Monte Carlo error), beside the median
    sd_km that the first seed's track reports."""
    rows = {}
    for name in floats:
        tracks = [pd.read_parquet(out_root / f"seed{seed}" / "default" / name / "track.parquet") for seed in seeds]
        lat, lon = np.mean([t["lat"] for t in tracks], axis=0), np.mean([t["lon"] for t in tracks], axis=0)
        offsets = [local_offsets_km(t["lat"].to_numpy(), t["lon"].to_numpy(), lat, lon) for t in tracks]
        spread = float(np.sqrt(np.mean(np.square(offsets).sum(axis=1)) * len(seeds) / (len(seeds) - 1)))
        rows[name] = {"spread_km": spread, "median_sd_km": float(np.median(tracks[0]["sd_km"]))}
    return pd.DataFrame.from_dict(rows, orient="index")


def seed_figures(table: pd.DataFrame) -> pd.DataFrame:
    """Per float, over the filter seeds: the smallest and largest RMSE, the most confidently
    wrong windows, and `rmse_unstable` where the RMSEs differ by more than `SEED_RMSE_GAP`."""
    by = table.groupby("float")
    figures = pd.DataFrame(
        {
            "rmse_min_km": by["rmse_km"].min(),
            "rmse_max_km": by["rmse_km"].max(),
            "confident_wrong_max": by["confident_wrong"].max(),
        }
    )
    gap_km, share = SEED_RMSE_GAP
    gap = figures["rmse_max_km"] - figures["rmse_min_km"]
    figures["rmse_unstable"] = gap > np.maximum(gap_km, share * figures["rmse_min_km"])
    return figures


def off_windows(out_root: Path, table: pd.DataFrame) -> pd.DataFrame:
    """Per float, the windows where its worst seed (largest RMSE) is more than
    `OFF_WINDOW_KM` farther off than its best: how many (`off_windows`), and how many of
    them that seed's track says it is unsure of (`off_said`: status in `FLAGGED`, or an
    sd_km at least half the error, the benchmark's test of a confidently wrong window
    turned round): the seed target's test, that a float whose seeds differ says so where
    they do."""
    rows = {}
    for name, runs in table.groupby("float"):
        worst, best = (int(runs.loc[runs["rmse_km"].idxmax(), "filter_seed"]),
                       int(runs.loc[runs["rmse_km"].idxmin(), "filter_seed"]))  # fmt: skip
        errors = {k: pd.read_csv(out_root / f"seed{k}" / f"errors_{name}.csv") for k in (worst, best)}
        track = out_root / f"seed{worst}" / "default" / str(name) / "track.parquet"
        flagged = pd.read_parquet(track, columns=["status"])["status"].isin(FLAGGED).to_numpy()
        error, sd = errors[worst]["error_km"].to_numpy(), errors[worst]["sd_km"].to_numpy()
        off = error - errors[best]["error_km"].to_numpy() > OFF_WINDOW_KM
        rows[name] = {"off_windows": int(off.sum()), "off_said": int((off & (flagged | (sd >= error / 2))).sum())}
    return pd.DataFrame.from_dict(rows, orient="index")


SPREAD_TEXT = (
    "spread_km: RMS distance of each seed's track from their mean; median_sd_km: the first seed's; "
    f"rmse_unstable: RMSEs more than max({SEED_RMSE_GAP[0]:g} km, {SEED_RMSE_GAP[1]:.0%} of the smallest) apart; "
    f"off_windows: the worst seed's windows more than {OFF_WINDOW_KM:g} km farther off than the best seed's, "
    f"off_said: those of them its track is unsure of ({', '.join(FLAGGED)}, or sd_km >= half the error)"
)
SPREAD_FORMATS: dict[str, Callable[[Any], str]] = {
    **{c: (lambda x: f"{x:.2f}") for c in ("spread_km", "median_sd_km", "rmse_min_km", "rmse_max_km")},
    "rmse_unstable": lambda x: "UNSTABLE" if x else "-",
}


class Target(NamedTuple):
    """One robustness target on one run: passed, the floats failing it, and the floats on
    which its reference fails the same test (None where the target is the reference's own
    figure times a margin, which the reference passes by definition); judged under several
    filter seeds, the seeds each of those floats fails under."""

    name: str
    passed: bool
    failing: list[str]
    reference: list[str] | None
    failing_seeds: dict[str, list[int]] | None = None
    reference_seeds: dict[str, list[int]] | None = None


def targets(table: pd.DataFrame) -> list[Target]:
    """The robustness targets, each relative to its reference on the same floats: the
    true-label filter for the track's (`ref_*`), the oracle's labels for the labels'."""

    def floats(where: pd.Series) -> list[str]:
        return list(table.loc[where, "float"])

    def inside(cover: pd.Series) -> pd.Series:
        return (cover >= COVERAGE_RANGE[0]) & (cover <= COVERAGE_RANGE[1])

    def worse(column: str, floor_km: float) -> list[str]:
        return floats(table[column] > np.maximum(floor_km, 1.2 * table[f"ref_{column}"]))

    cover = f"95%-ellipse coverage in [{COVERAGE_RANGE[0]:.0%}, {COVERAGE_RANGE[1]:.0%}] wherever the reference's is"
    wrong, ref_wrong = int(table["confident_wrong"].sum()), int(table["ref_confident_wrong"].sum())
    found = [
        ("p95 <= max(15 km, 1.2x the true-label filter's)", worse("p95_km", 15.0), floats(table["ref_p95_km"] > 15)),
        ("RMSE <= max(5 km, 1.2x the true-label filter's)", worse("rmse_km", 5.0), floats(table["ref_rmse_km"] > 5)),
        ("labels right within 1 point of the oracle's (labels at the true track)",
         floats(table["labels"] < table["labels_oracle"] - 0.01), None),
        (cover, floats(inside(table["ref_cover95"]) & ~inside(table["cover95"])),
         floats(~inside(table["ref_cover95"]))),
    ]  # fmt: skip
    result = [Target(name, not failing, failing, reference) for name, failing, reference in found]
    more_wrong = floats(table["confident_wrong"] > table["ref_confident_wrong"])
    result.append(
        Target(
            f"confidently wrong windows no more than the true-label filter's ({wrong} against {ref_wrong})",
            wrong <= ref_wrong,
            more_wrong,
            floats(table["ref_confident_wrong"] > 0),
        )
    )
    return result


def worst_seed_targets(per_seed: dict[int, list[Target]]) -> list[Target]:
    """The targets under every filter seed (`per_seed`: each seed's `targets`): one holds only
    if it holds under each seed; its floats are those failing it under any seed."""
    result = []
    for k, first in enumerate(next(iter(per_seed.values()))):
        runs = {seed: found[k] for seed, found in per_seed.items()}
        failing = _seeds_by_float({seed: t.failing for seed, t in runs.items()})
        reference = None
        if first.reference is not None:
            reference = _seeds_by_float({seed: t.reference or [] for seed, t in runs.items()})
        passed = all(t.passed for t in runs.values())
        name = _worst_seed_name(runs)
        refs = None if reference is None else list(reference)
        result.append(Target(name, passed, list(failing), refs, failing, reference))
    return result


def _seeds_by_float(floats_of: dict[int, list[str]]) -> dict[str, list[int]]:
    """Per float named under any seed (`floats_of`: the floats of each seed), those seeds."""
    seeds: dict[str, list[int]] = {}
    for seed, floats in floats_of.items():
        for name in floats:
            seeds.setdefault(name, []).append(seed)
    return dict(sorted(seeds.items()))


def _worst_seed_name(runs: dict[int, Target]) -> str:
    """A target's name under every seed: its name, or, where the seeds' names differ in their
    last parenthesis (e.g. the confidently wrong windows' counts), those counts per seed."""
    names = {t.name for t in runs.values()}
    if len(names) == 1:
        return names.pop()
    base = next(iter(runs.values())).name.rsplit(" (", 1)[0]
    counts = "; ".join(f"seed {seed}: {t.name.rsplit(' (', 1)[1].rstrip(')')}" for seed, t in runs.items())
    return f"{base} ({counts})"


def _float_list(floats: list[str], seeds: dict[str, list[int]] | None) -> str:
    """`floats` joined, each with the seeds it fails under where known."""
    if seeds is None:
        return ", ".join(floats)
    return ", ".join(
        f"{name} [seed{'s' if len(seeds[name]) > 1 else ''} {' '.join(map(str, seeds[name]))}]" for name in floats
    )


def target_line(target: Target) -> str:
    """`PASS: name` or `FAIL: name (n: floats)`, with the reference's own failures of the test
    (and, under several filter seeds, the seeds each float fails under)."""
    line = f"{'PASS' if target.passed else 'FAIL'}: {target.name}"
    if target.failing:
        floats = _float_list(target.failing, target.failing_seeds)
        line += f" ({'floats beyond it' if target.passed else len(target.failing)}: {floats})"
    if target.reference is not None:
        line += f"; the reference itself: {len(target.reference)}" + (
            f" ({_float_list(target.reference, target.reference_seeds)})" if target.reference else ""
        )
    return line


def _parse_args() -> argparse.Namespace:
    """The command line, checked; `fault_sets`, `knobs` and the stress run's `filter_seeds` resolved."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--floats", type=int, default=24)
    parser.add_argument("--days", type=int, default=240)
    parser.add_argument("--seed", type=int, nargs="+", default=[2026], help="the missions' seeds (scenario seeds)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", type=Path, help="keep the missions and outputs here")
    parser.add_argument("--config", type=Path, action="append", default=[], help="an extra config layer")
    parser.add_argument("--only", nargs="+", help="float ids to run")
    parser.add_argument("--csv", type=Path, help="write the per-float table here")
    parser.add_argument(
        "--filter-seeds",
        type=int,
        nargs="+",
        help=f"track every float with each [filter] seed; the targets must hold under every one (default "
        f"{' '.join(map(str, FILTER_SEEDS))}; one value, e.g. 0, the configured default, for a single seed; "
        "not with --faults, which keeps the configured seed)",
    )
    parser.add_argument("--report", type=Path, help="write the results into this Markdown file's robustness section")
    parser.add_argument(
        "--faults",
        nargs="+",
        help=f"metadata fault sets: each (one per kind), all (every kind together), KIND[,KIND...]; {FAULT_KINDS}",
    )
    parser.add_argument(
        "--knob",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="a stress generator knob (a number field of rafostrack.sim.stress.StressConfig), e.g. clutter_taper=0.8",
    )
    parser.add_argument(
        "--never-surfaced",
        type=float,
        help=f"share of floats with no end fix and no end clock (default {NEVER_SURFACED_SHARE} with --faults, else 0)",
    )
    args = parser.parse_args()
    if args.faults and args.filter_seeds:
        parser.error("--faults tracks with the configured [filter] seed; drop --filter-seeds")
    if not args.faults:
        args.filter_seeds = list(dict.fromkeys(args.filter_seeds or FILTER_SEEDS))
    try:
        args.fault_sets = fault_sets(args.faults) if args.faults else []
        args.knobs = dict(_knob(text) for text in args.knob)
    except ValueError as error:
        parser.error(str(error))
    return args


def _knob(text: str) -> tuple[str, float | int]:
    """`NAME=VALUE` as a stress knob (a number field of `StressConfig`)."""
    name, _, value = text.partition("=")
    numbers = {f.name: f.type for f in dataclasses.fields(StressConfig) if f.type in ("int", "float")}
    if name not in numbers:
        raise ValueError(f"--knob {text}: not a number knob of StressConfig; known: {', '.join(sorted(numbers))}")
    return name, int(value) if numbers[name] == "int" else float(value)


def _output_root(args: argparse.Namespace) -> Path:
    root = args.out or Path(tempfile.mkdtemp(prefix="rafostrack-robustness-"))
    root.mkdir(parents=True, exist_ok=True)
    return root


def run_tasks(fn: Callable[[Any], Any], tasks: list, workers: int) -> list:
    """`fn` over `tasks`, in a pool of `workers` processes (single-threaded maths) when more than 1."""
    if workers > 1:
        context = multiprocessing.get_context("forkserver")  # fresh workers: numba single-threaded too
        with single_threaded_math(), ProcessPoolExecutor(workers, mp_context=context) as pool:
            return list(pool.map(fn, tasks))
    return [fn(t) for t in tasks]


def _only(files: list[Path], only: list[str] | None) -> list[Path]:
    return [f for f in files if f.stem in set(only)] if only else files


@dataclasses.dataclass(frozen=True)
class SeedResult:
    """One scenario seed's runs: the targets by run (the stress run's under every filter seed,
    or the correct tables' run and each fault set's), the report's text, the per-float table
    and the number of runs."""

    seed: int
    targets: dict[str, list[Target]]
    sections: list[str]
    table: pd.DataFrame
    runs: int


def main() -> None:
    args = _parse_args()
    root, started = _output_root(args), time.perf_counter()
    run = run_faults if args.fault_sets else run_stress
    results = [run(args, seed, root / f"seed{seed}" if len(args.seed) > 1 else root) for seed in args.seed]
    sections = [] if len(results) == 1 else [_print_scenario_summary(results)]
    for result in results:
        sections += ([] if len(results) == 1 else [f"#### Missions of seed {result.seed}"]) + result.sections
    runs = sum(r.runs for r in results)
    print(f"\n{runs} runs in {time.perf_counter() - started:.0f} s ({args.workers} workers); outputs in {root}")
    if args.csv:
        pd.concat([r.table.assign(scenario_seed=r.seed) for r in results]).to_csv(args.csv, index=False)
    if args.report:
        setup = (
            _setup_text(args) + f" {runs} runs in {time.perf_counter() - started:.0f} s with {args.workers} workers."
        )
        write_section(
            args.report, "robustness-faults" if args.fault_sets else "robustness", "\n\n".join([setup, *sections])
        )


def _setup_text(args: argparse.Namespace) -> str:
    """The report's first paragraph: what was run."""
    seeds = f"seed{'s' if len(args.seed) > 1 else ''} {', '.join(map(str, args.seed))}"
    layers = f" plus {', '.join(map(str, args.config))}" if args.config else ""
    if not args.fault_sets:
        filter_seeds = ", ".join(map(str, args.filter_seeds))
        return (
            f"{args.floats} stress floats of {args.days} days per scenario seed (missions of {seeds}; the defaults "
            f"were tuned on seed 2026), tracked with the default settings{layers} and with the true labels (the "
            f"true-label filter, `ref_*`), each under the filter seeds {filter_seeds} (`[filter] seed`). The targets "
            "are judged under every filter seed: a target holds only if it holds under each one, each seed's run "
            "against the true-label filter of the same seed."
        )
    share = NEVER_SURFACED_SHARE if args.never_surfaced is None else args.never_surfaced
    return (
        f"{args.floats} stress floats of {args.days} days per scenario seed (missions of {seeds}; true clocks ending "
        f"{CLOCK_END_OFFSET_S[0]:g}..{CLOCK_END_OFFSET_S[1]:g} s off, {share:.0%} of floats never surfaced), "
        f"tracked with the default settings{layers} with correct tables (`ok_*`; beside the true-label filter, "
        "`ref_*`) and with faulted ones."
    )


def _print_scenario_summary(results: list[SeedResult]) -> str:
    """Print, per run and target, the floats failing it on each scenario seed (and, where the
    target has one, how many its reference fails); the report's text."""
    rows = []
    for run in results[0].targets:
        for k, target in enumerate(results[0].targets[run]):
            row = {"run": run or "default", "target": target.name.split(" (")[0]}
            for result in results:
                t = result.targets[run][k]
                ref = "" if t.reference is None else f" (ref {len(t.reference)})"
                row[f"seed {result.seed}"] = f"{'pass' if t.passed else 'FAIL'} {len(t.failing)}{ref}"
            rows.append(row)
    summary = pd.DataFrame(rows)
    what = "pass/FAIL and the floats beyond each target (under every filter seed; ref: the reference's own, same test)"
    print(f"\nper scenario seed: {what}")
    print(summary.to_string(index=False))
    head = f"**Per scenario seed**: {what}:"
    return head + "\n\n" + markdown_table(summary, {})


def run_stress(args: argparse.Namespace, scenario_seed: int, root: Path) -> SeedResult:
    """The stress benchmark on the missions of `scenario_seed`: every float by default and
    with its true labels, per filter seed."""
    root.mkdir(parents=True, exist_ok=True)
    knobs = {**args.knobs, **({"never_surfaced_share": args.never_surfaced} if args.never_surfaced else {})}
    files = _only(make_missions(root / "missions", args.floats, args.days, scenario_seed, knobs), args.only)
    seeds: list[int] = args.filter_seeds
    tasks = [(f, root / "out", tuple(args.config), seed) for seed in seeds for f in files]
    (root / "out").mkdir(exist_ok=True)
    scored = run_tasks(score, tasks, args.workers)
    table = pd.DataFrame([row for row, _ in scored])
    labels = pd.concat([scores for _, scores in scored], ignore_index=True)
    per_seed: dict[int, list[Target]] = {}
    sections: list[str] = []  # the report's text: the verdict under every seed first, then one per seed
    for seed in seeds:
        per_seed[seed], section = _print_seed(seed, _of_seed(table, seed), _of_seed(labels, seed))
        sections.append(section)
    run = f"filter seed{'s' if len(seeds) > 1 else ''} {', '.join(map(str, seeds))}"
    if len(seeds) == 1:
        return SeedResult(scenario_seed, {run: per_seed[seeds[0]]}, sections, table, len(table))
    worst = worst_seed_targets(per_seed)
    sections.insert(0, _print_worst_seed(root / "out", seeds, worst, table, [f.stem for f in files]))
    return SeedResult(scenario_seed, {run: worst}, sections, table, len(table))


def _print_seed(seed: int | None, runs: pd.DataFrame, labels: pd.DataFrame) -> tuple[list[Target], str]:
    """Print one filter seed's table (`stress_columns` of `runs`), targets, confident answers
    and label reliability; the targets and the report's text."""
    runs = runs.copy()
    counts = sorted(c for c in runs.columns if c.startswith("n_"))
    runs[counts] = runs[counts].fillna(0).astype(int)  # a status no window of a float had
    cols = ["float", "geometry", "clutter", "rmse_km", "p95_km", "max_km", "labels", "labels_oracle", "cover95",
            "ess_med", "ref_rmse_km", "ref_p95_km", "ratio", "ref_cover95", "seconds", *counts, "confident_wrong",
            "ref_confident_wrong", "wrong_p99", "expected_p99"]  # fmt: skip
    pd.set_option("display.width", 200)
    if seed is not None:
        print(f"\n[filter] seed = {seed}")
    print(runs[cols].to_string(index=False, float_format=lambda x: f"{x:.3f}"))
    failing = targets(runs)
    notes = [target_line(target) for target in failing]
    wrong = runs.loc[runs["confident_wrong"] > 0, ["float", "confident_wrong"]]
    notes.append(
        f"confidently wrong windows (> 30 km off, sd_km under half the error): {wrong['confident_wrong'].sum()}"
        f" of {runs['windows'].sum()}"
        + (f" ({', '.join(f'{f} {n}' for f, n in wrong.itertuples(index=False))})" if len(wrong) else "")
    )
    notes.append(
        f"labels given with p >= {CONFIDENT_PROB}: {runs['wrong_p99'].sum()} wrong, "
        f"{runs['expected_p99'].sum():.1f} expected"
    )
    print(("" if seed is None else f"targets under [filter] seed {seed} alone:\n") + "\n".join(notes))
    print("label reliability, all floats (a calibrated labeller: right = mean_prob in every bin):")
    reliability = label_reliability(labels)
    print(reliability.to_string(index=False, float_format=lambda x: f"{x:.4f}"))
    return failing, _seed_report(seed, runs[cols], notes, reliability)


def _print_worst_seed(
    out_root: Path, seeds: list[int], worst: list[Target], table: pd.DataFrame, floats: list[str]
) -> str:
    """Print the targets under every filter seed and the seeds' spread per float; the report's text."""
    notes = [target_line(target) for target in worst]
    print(f"\ntargets under every filter seed ({', '.join(map(str, seeds))}; [seeds]: those a float fails under):")
    print("\n".join(notes))
    spread = seed_spread(out_root, seeds, floats).join(seed_figures(table)).join(off_windows(out_root, table))
    unstable = list(spread.index[spread["rmse_unstable"]])
    unsaid = spread["off_windows"] - spread["off_said"]
    ratio = spread["spread_km"] / spread["median_sd_km"]
    print(f"\nper float over the seeds ({SPREAD_TEXT}):")
    print(spread.rename_axis("float").reset_index().to_string(index=False, formatters=SPREAD_FORMATS))
    print(
        f"median spread {spread['spread_km'].median():.2f} km, {ratio.median():.0%} of the median sd_km "
        f"(largest: {ratio.idxmax()}, {ratio.max():.0%}); RMSE unstable between seeds: {len(unstable)}"
        + (f" ({', '.join(unstable)})" if unstable else "")
        + f"; windows off in a float's worst seed: {int(spread['off_windows'].sum())}, said so "
        f"{int(spread['off_said'].sum())} (floats with some not said: {int((unsaid > 0).sum())})"
    )
    return _worst_seed_report(seeds, notes, spread)


# --------------------------------------------------------------------------------------
# Metadata faults (--faults)


def fault_sets(words: list[str]) -> list[tuple[str, tuple[str, ...]]]:
    """The mission sets of `--faults`, one or more per word: `all` (every kind at once),
    `each` (one set per kind) or `KIND[,KIND...]` (those kinds together)."""
    sets: list[tuple[str, tuple[str, ...]]] = []
    for word in words:
        if word == "all":
            sets.append(("all", FAULT_KINDS))
        elif word == "each":
            sets += [(kind, (kind,)) for kind in FAULT_KINDS]
        else:
            kinds = check_kinds(k.strip() for k in word.split(","))
            sets.append(("+".join(kinds), kinds))
    return list(dict.fromkeys(sets))


def faulted(sim: Simulated, kinds: tuple[str, ...]) -> Simulated:
    """`sim` with the faults `kinds` in its tables (the generator `simulate_stress` would use)."""
    cfg = dataclasses.replace(sim.cfg, faults=kinds)
    return dataclasses.replace(sim, mission=with_faults(sim.mission, cfg, substream(sim.rng, FAULT_STREAM)), cfg=cfg)


def metadata_checks(run_json: Path) -> list[dict[str, Any]]:
    """run.json's "metadata_checks" (none where the key is missing)."""
    return list(json.loads(Path(run_json).read_text()).get("metadata_checks", []))


def _alarm_text(checks: list[dict[str, Any]]) -> str:
    return "; ".join(f"{Path(str(c['file'])).name} {c['id']} {c['field']}" for c in checks)


def float_faults(float_file: Path) -> list[InjectedFault]:
    """The faults injected into a float's mission that are its own or its sources'."""
    faults = read_faults(float_file.parent / "truth" / "faults.json")
    return [f for f in faults if f.file == "beacons.csv" or f.id == float_file.stem]


def observable_faults(float_file: Path, faults: list[InjectedFault]) -> list[InjectedFault]:
    """Those of `faults` the float's stored arrivals can show (`faults.observable`)."""
    arrivals = pd.read_csv(float_file, usecols=["time", "beacon_id"])
    return [f for f in faults if observable(f, arrivals)]


def score_faulted(task: tuple[Path, Path, tuple[Path, ...]]) -> dict[str, Any]:
    """Track one float of a faulted mission by default; its figures, the faults (its own and
    the sources') its metadata checks name, and their false alarms."""
    float_file, out_root, config_files = task
    truth, events = read_truth(float_file)
    inputs = TrackInputs(float_file, config_files=config_files, overrides={"filter": {}})
    track = track_float(inputs, out_root, plots=False).output.track
    mine = float_faults(float_file)
    shown = observable_faults(float_file, mine)
    checks = metadata_checks(out_root / float_file.stem / "run.json")
    unnamed, alarms = unnamed_faults(shown, checks), false_alarms(mine, checks)
    return {
        "float": float_file.stem,
        "geometry": events["geometry"],
        "clutter": events["clutter_rate"],
        "surfaced": bool(events.get("surfaced", True)),
        **{k: v for k, v in position_figures(track, truth).items() if k != "max_km"},
        "faults": len(shown),
        "unobservable": len(mine) - len(shown),
        "mission": float_file.parent.name,
        "named": len(shown) - len(unnamed),
        "false_alarms": len(alarms),
        "unnamed_list": "; ".join(f"{f.kind} ({f.file} {f.id} {f.field})" for f in unnamed),
        "false_alarm_list": _alarm_text(alarms),
    }


def reference_rows(rows: list[dict[str, Any]], out_root: Path, files: list[Path]) -> pd.DataFrame:
    """The correct tables' runs (`score` rows) by float, with their false alarms (every
    contradicted value: the tables were right), and with the mission's pooled ones."""
    table = pd.DataFrame(rows).set_index("float")
    checks = {name: metadata_checks(out_root / "default" / name / "run.json") for name in table.index}
    alarms = {name: false_alarms([], checks[name]) for name in table.index}
    found = mission_alarms(out_root / "default", files)
    table["false_alarms"] = [len(alarms[name]) for name in table.index]
    mission_of = {f.stem: f.parent.name for f in files}
    table["false_alarms_mission"] = [
        len(distinct(false_alarms([], checks[name] + found[mission_of[name]]))) for name in table.index
    ]
    table["false_alarm_list"] = [_alarm_text(alarms[name]) for name in table.index]
    return table


def mission_alarms(out_root: Path, files: list[Path]) -> dict[str, list[dict[str, Any]]]:
    """Per mission, the sources' values a batch finds contradicted (`batch.findings`: on one
    float or more, or on their arrivals together: a source's offset, drift or position
    pooled over the floats that hear it), as contradicted metadata_checks entries (a
    floats.csv value is its float's own: not the mission's)."""
    checks: dict[str, list] = {}
    for f in files:
        run = json.loads((out_root / f.stem / "run.json").read_text())
        checks.setdefault(f.parent.name, []).extend(parse_checks(run, f.stem))
    return {
        mission: [as_contradicted(x) for x in mission_findings(mission, found) if x.of_source]
        for mission, found in checks.items()
    }


def as_contradicted(finding: Finding) -> dict[str, Any]:
    """A mission's finding as a contradicted metadata_checks entry (`faults.names` reads it)."""
    return {
        "file": finding.file,
        "id": finding.id,
        "field": finding.field,
        "outcome": "contradicted",
        "alternatives": finding.alternatives,
        "other_sources": finding.other_sources,
    }


def distinct(entries: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """`entries` once per table value (file name, id, field)."""
    seen = {(Path(e["file"]).name, e["id"], e["field"]): e for e in entries}
    return list(seen.values())


def with_mission_findings(rows: list[dict[str, Any]], out_root: Path, files: list[Path]) -> list[dict[str, Any]]:
    """`rows` with the faults named and the false alarms counting the mission's findings
    too (`mission_alarms`: a finding names the value for every float of the mission):
    `named_mission`, `false_alarms_mission`."""
    found, by_stem = mission_alarms(out_root, files), {f.stem: f for f in files}
    for row in rows:
        float_file = by_stem[row["float"]]
        mine = float_faults(float_file)
        shown = observable_faults(float_file, mine)
        own = metadata_checks(out_root / float_file.stem / "run.json") + found[row["mission"]]
        row["named_mission"] = len(shown) - len(unnamed_faults(shown, own))
        row["false_alarms_mission"] = len(distinct(false_alarms(mine, own)))
    return rows


FAULT_TARGET_KEYS = (
    "p95",
    "rmse",
    "coverage",
    "confident_wrong",
    "unnamed",
    "unnamed_mission",
    "false_alarm",
)  # fault_targets' order
FAULT_COLUMNS = ["rmse_km", "p95_km", "cover95", "confident_wrong", "false_alarms", "false_alarms_mission"]


def fault_table(reference: pd.DataFrame, rows: list[dict[str, Any]]) -> pd.DataFrame:
    """The faulted runs' rows beside the correct tables' figures (`ok_*`)."""
    ok = reference[[*FAULT_COLUMNS, "false_alarm_list"]].add_prefix("ok_")
    return pd.DataFrame(rows).join(ok, on="float")


def fault_targets(table: pd.DataFrame) -> list[Target]:
    """The metadata-fault targets against the correct tables' runs: (name, passed, floats failing)."""

    def floats(where: pd.Series) -> list[str]:
        return list(table.loc[where, "float"])

    def inside(cover: pd.Series) -> pd.Series:
        return (cover >= COVERAGE_RANGE[0]) & (cover <= COVERAGE_RANGE[1])

    def worse(column: str, floor_km: float) -> pd.Series:
        return table[column] > np.maximum(floor_km, 1.2 * table[f"ok_{column}"])

    alarms = int(table["false_alarms_mission"].sum() + table["ok_false_alarms_mission"].sum())
    checks = [
        ("p95 <= max(15 km, 1.2x the correct tables')", floats(worse("p95_km", 15.0))),
        ("RMSE <= max(5 km, 1.2x the correct tables')", floats(worse("rmse_km", 5.0))),
        (f"95%-ellipse coverage in [{COVERAGE_RANGE[0]:.0%}, {COVERAGE_RANGE[1]:.0%}] wherever the correct tables' is",
         floats(inside(table["ok_cover95"]) & ~inside(table["cover95"]))),
        ("confidently wrong windows no more than the correct tables'",
         floats(table["confident_wrong"] > table["ok_confident_wrong"])),
        ("every injected fault the float's arrivals show named", floats(table["named"] < table["faults"])),
        ("every injected fault named, with the mission's floats together",
         floats(table["named_mission"] < table["faults"])),
    ]  # fmt: skip
    result = [Target(name, not failing, failing, None) for name, failing in checks]
    allowed = FALSE_ALARMS_PER_FLOAT * len(table)
    any_alarm = floats((table["false_alarms_mission"] > 0) | (table["ok_false_alarms_mission"] > 0))
    name = f"at most one false alarm per 100 floats ({alarms}, both runs)"
    result.append(Target(name, alarms <= allowed, any_alarm, None))
    return result


def _fault_notes(table: pd.DataFrame, found: list[Target]) -> list[str]:
    """The lines under a fault set's table: the targets, then per float the faults not named
    and the false alarms."""
    notes = [target_line(target) for target in found]
    for row in table.itertuples(index=False):
        if row.unnamed_list:
            notes.append(f"{row.float}: not named: {row.unnamed_list}")
        if row.false_alarm_list:
            notes.append(f"{row.float}: false alarms: {row.false_alarm_list}")
        if row.ok_false_alarm_list:
            notes.append(f"{row.float}: false alarms with the correct tables: {row.ok_false_alarm_list}")
    return notes


FAULT_TABLE = ["float", "geometry", "clutter", "surfaced", "ok_rmse_km", "rmse_km", "ok_p95_km", "p95_km", "ok_cover95",
               "cover95", "ok_confident_wrong", "confident_wrong", "faults", "unobservable", "named", "named_mission",
               "false_alarms", "ok_false_alarms"]  # fmt: skip


def run_faults(args: argparse.Namespace, scenario_seed: int, root: Path) -> SeedResult:
    """The fault benchmark on the missions of `scenario_seed`: every float with the correct
    tables (`score`: the stress benchmark's table and targets), then with each fault set's
    tables (`score_faulted`); per set the table and the targets."""
    share = NEVER_SURFACED_SHARE if args.never_surfaced is None else args.never_surfaced
    knobs = {**args.knobs, "clock_end_offset_s": CLOCK_END_OFFSET_S, "never_surfaced_share": share}
    missions = simulate_missions(args.floats, args.days, scenario_seed, knobs)
    correct = _only(write_missions(root / "missions" / "correct", missions), args.only)
    (root / "out" / "correct").mkdir(parents=True, exist_ok=True)
    configs = tuple(args.config)
    scored = run_tasks(score, [(f, root / "out" / "correct", configs, None) for f in correct], args.workers)
    rows = [row for row, _ in scored]
    print(f"\ncorrect tables (missions of seed {scenario_seed}):")
    found, section = _print_seed(None, pd.DataFrame(rows), pd.concat([labels for _, labels in scored]))
    targets_by_run, sections = (
        {"correct tables": found},
        [f"**Correct tables** (missions of seed {scenario_seed}):", section],
    )
    reference = reference_rows(rows, root / "out" / "correct", correct)
    tables = {}
    for name, kinds in args.fault_sets:
        files = _only(write_missions(root / "missions" / name, [faulted(sim, kinds) for sim in missions]), args.only)
        (root / "out" / name).mkdir(parents=True, exist_ok=True)
        faulted_rows = run_tasks(score_faulted, [(f, root / "out" / name, configs) for f in files], args.workers)
        faulted_rows = with_mission_findings(faulted_rows, root / "out" / name, files)
        tables[name] = fault_table(reference, faulted_rows)
        targets_by_run[name] = fault_targets(tables[name])
        sections.append(_print_fault_set(name, tables[name]))
    if len(tables) > 1:
        sections.append(_print_fault_summary(tables))
    table = pd.concat([t.assign(fault_set=name) for name, t in tables.items()])
    return SeedResult(scenario_seed, targets_by_run, sections, table, 2 * len(correct) + len(table))


def _print_fault_set(name: str, table: pd.DataFrame) -> str:
    """Print one fault set's table and targets; the report's text."""
    notes = _fault_notes(table, fault_targets(table))
    print(
        f"\nfaults: {name} ({int(table['faults'].sum())} over the floats that can show them, a source's once per "
        f"float; {int(table['unobservable'].sum())} not shown by the float's arrivals)"
    )
    pd.set_option("display.width", 200)
    print(table[FAULT_TABLE].to_string(index=False, float_format=lambda x: f"{x:.3f}"))
    print("\n".join(notes))
    percent = {c: (lambda x: f"{x:.1%}") for c in ("cover95", "ok_cover95")}
    km = {c: (lambda x: f"{x:.2f}") for c in ("rmse_km", "p95_km", "ok_rmse_km", "ok_p95_km")}
    lines = [f"**Faults: {name}** (km; `ok_*`: the same float with correct tables):", ""]
    lines += [markdown_table(table[FAULT_TABLE], {**percent, **km, "clutter": lambda x: f"{x:g}"}), ""]
    return "\n".join(lines + [f"- {note}" for note in notes])


def _print_fault_summary(tables: dict[str, pd.DataFrame]) -> str:
    """Print, per fault set, how many floats fail each target (`FAULT_TARGET_KEYS`); the report's text."""
    rows = {
        name: {key: len(target.failing) for key, target in zip(FAULT_TARGET_KEYS, fault_targets(t), strict=True)}
        for name, t in tables.items()
    }
    summary = pd.DataFrame.from_dict(rows, orient="index").rename_axis("faults").reset_index()
    print("\nfloats failing each target, per fault set:")
    print(summary.to_string(index=False))
    return "**Floats failing each target, per fault set:**\n\n" + markdown_table(summary, {})


def _seed_report(seed: int | None, runs: pd.DataFrame, notes: list[str], reliability: pd.DataFrame) -> str:
    """The report's text for one filter seed: the per-float table, the targets and the label reliability."""
    title = "Per float" + (f" (`[filter] seed = {seed}`)" if seed is not None else "")
    percent = {c: (lambda x: f"{x:.1%}") for c in ("labels", "labels_oracle", "cover95", "ref_cover95")}
    wide = {c: (lambda x: f"{x:.1f}") for c in ("ess_med", "seconds", "expected_p99")}
    given = {c: (lambda x: f"{x:.2f}") for c in ("rmse_km", "p95_km", "max_km", "ref_rmse_km", "ref_p95_km", "ratio")}
    given["clutter"] = lambda x: f"{x:g}"
    lines = [f"**{title}** (km; `labels_oracle`: labels at the true track; `cover95`: 95%-ellipse coverage):", ""]
    targets_title = "Targets and confident answers" if seed is None else "This seed's targets and confident answers"
    lines += [markdown_table(runs, {**percent, **wide, **given}), "", f"**{targets_title}:**", ""]
    lines += [f"- {note}" for note in notes]
    lines += ["", "**Label reliability**, all floats (a calibrated labeller: right = mean_prob in every bin):", ""]
    lines.append(markdown_table(reliability, {c: (lambda x: f"{x:.4f}") for c in ("mean_prob", "right")}))
    return "\n".join(lines)


def _worst_seed_report(seeds: list[int], notes: list[str], spread: pd.DataFrame) -> str:
    """The report's text over several filter seeds: the targets under every seed, the seeds' spread per float."""
    lines = [
        f"**Targets under every filter seed** ({', '.join(map(str, seeds))}): a target holds only if it holds "
        "under each seed, each seed's run against the true-label filter of the same seed; the floats failing it "
        "under any seed, with those seeds in brackets:",
        "",
    ]
    lines += [f"- {note}" for note in notes]
    lines += ["", f"**Per float over the filter seeds** ({SPREAD_TEXT}):", ""]
    lines.append(markdown_table(spread.rename_axis("float").reset_index(), SPREAD_FORMATS))
    return "\n".join(lines)


if __name__ == "__main__":
    main()
