"""The default method's time on the sample float: this working tree against a git revision.

On a shared machine a track's wall time moves by 10-15% from one process to the next, so a
change is timed beside the code before it, not against a figure from another day. The
revision is checked out in a temporary git worktree; each round times one track with each
tree, in separate processes on the same core (one kernel thread, one math-library thread),
in the order new-old on odd rounds and old-new on even ones (a drift of the machine then
weighs on both). A process first tracks the float at 100 particles (numba's first
compilation, and the caches, out of the timed track), then once at `--particles`.

Printed per round: each tree's seconds (the whole method, and its filter, smoother and
calibration parts) and the ratio new/old; then the ratio of the fastest rounds, the
median ratio and the spread of the rounds' ratios. A change has made the method faster
when the ratios of all rounds lie below 1 and below the spread of the machine: on the
2-core machine of docs/validation.md, the same code against itself (`REV` = HEAD) gave
0.977-0.988 over three rounds at 1000 particles, so a few percent is not a change. Also
printed: whether the two trees' tracks and labels are the same bits (a change that keeps
them is judged on time alone; otherwise the robustness run judges its accuracy,
`benchmarks/robustness.py`). With `--all-cores` the processes run as `rafostrack track` runs
on this machine: on every core, with numba's threads and part of the work forked beside
(`rafostrack.run.forked`).

    python benchmarks/compare.py REV [--particles 1000] [--rounds 3] [--float-file FILE] [--core 0] [--all-cores]
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from report import REPO

from rafostrack.sim.scenarios import sample_mission_dir

SAMPLE = sample_mission_dir() / "float767.csv"
WARM_UP_PARTICLES = 100
PARTS = ("total_s", "filter_s", "smoother_s", "calib_s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("rev", nargs="?", help="the git revision to compare against (e.g. HEAD, main~1)")
    parser.add_argument("--particles", type=int, default=1000)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--float-file", type=Path, default=SAMPLE)
    parser.add_argument("--core", type=int, default=0, help="the CPU core the timed processes run on")
    parser.add_argument("--all-cores", action="store_true", help="time on every core, as `rafostrack track` runs")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        if hasattr(os, "sched_setaffinity") and not args.all_cores:  # Linux: this process on one core
            os.sched_setaffinity(0, {args.core})
        print(json.dumps(_timed_track(args.float_file, args.particles)))
        return
    if args.rev is None:
        parser.error("give the git revision to compare against")
    with tempfile.TemporaryDirectory(prefix="rafostrack-compare-") as scratch:
        old_tree = Path(scratch) / "old"
        subprocess.run(["git", "worktree", "add", "--detach", str(old_tree), args.rev], cwd=REPO, check=True,
                       capture_output=True)  # fmt: skip
        try:
            _compare(REPO, old_tree, args)
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(old_tree)], cwd=REPO, capture_output=True)


def _compare(new_tree: Path, old_tree: Path, args: argparse.Namespace) -> None:
    """Time the rounds (module docstring) and print them, the ratios and the outputs' identity."""
    where = "every core" if args.all_cores else f"core {args.core}"
    print(f"{args.float_file.name}, {args.particles} particles, {where}: new = this working tree, "
          f"old = {args.rev}")  # fmt: skip
    print(f"{'round':>5} {'tree':>4} " + " ".join(f"{p:>10}" for p in PARTS) + f" {'new/old':>8}")
    runs: dict[str, list[dict]] = {"new": [], "old": []}
    for k in range(args.rounds):
        order = [("new", new_tree), ("old", old_tree)]
        for name, tree in order if k % 2 == 0 else order[::-1]:
            runs[name].append(_child(tree, args))
        for name in ("new", "old"):
            run = runs[name][-1]
            ratio = f"{run['total_s'] / runs['old'][-1]['total_s']:8.3f}" if name == "new" else ""
            print(f"{k + 1:5d} {name:>4} " + " ".join(f"{run[p]:10.2f}" for p in PARTS) + f" {ratio}", flush=True)
    ratios = [n["total_s"] / o["total_s"] for n, o in zip(runs["new"], runs["old"], strict=True)]
    fastest = min(r["total_s"] for r in runs["new"]) / min(r["total_s"] for r in runs["old"])
    print(f"new/old: fastest rounds {fastest:.3f}, median {statistics.median(ratios):.3f}, "
          f"rounds {min(ratios):.3f}-{max(ratios):.3f}")  # fmt: skip
    same = runs["new"][0]["outputs"] == runs["old"][0]["outputs"]
    print("outputs: the same bits" if same else "outputs: different (judge the accuracy with benchmarks/robustness.py)")


def _child(tree: Path, args: argparse.Namespace) -> dict:
    """One timed track in a process of its own with `tree`'s package, on `args.core` (or on
    every core)."""
    one_thread = dict.fromkeys(("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"), "1")
    env = {**os.environ, "PYTHONPATH": str(tree), **({} if args.all_cores else one_thread)}
    command = [sys.executable, str(Path(__file__).resolve()), "--child", "--particles", str(args.particles),
               "--float-file", str(args.float_file.resolve()), "--core", str(args.core)]  # fmt: skip
    if args.all_cores:
        command.append("--all-cores")
    done = subprocess.run(command, env=env, cwd=tree, capture_output=True, text=True)
    if done.returncode != 0:
        sys.exit(f"the track with {tree} failed:\n{done.stderr.strip()}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def _timed_track(float_file: Path, particles: int) -> dict:
    """The method's seconds on `float_file` at `particles` (after a warm-up track at
    `WARM_UP_PARTICLES`), and a digest of its track and labels."""
    from rafostrack.config import with_overrides
    from rafostrack.run.method import track_record
    from rafostrack.run.one_float import TrackInputs, load_float

    loaded = load_float(TrackInputs(float_file))

    def problem(n: int):
        return loaded.problem.with_config(with_overrides(loaded.problem.config, filter={"particles": n}))

    track_record(problem(WARM_UP_PARTICLES), loaded.record)
    started = time.perf_counter()
    out = track_record(problem(particles), loaded.record)
    total_s = time.perf_counter() - started
    digest = hashlib.sha256()
    for frame in (out.track, out.labels):
        digest.update(frame.to_csv(index=False, float_format="%.17g").encode())
    return {"total_s": total_s, "filter_s": out.seconds.filter_s, "smoother_s": out.seconds.smoother_s,
            "calib_s": out.seconds.calibrate_s, "outputs": digest.hexdigest()}  # fmt: skip


if __name__ == "__main__":
    main()
