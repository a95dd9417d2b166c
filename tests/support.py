"""Helpers shared by the test modules: small CSV missions, error capture, fuzz settings.

(Fixtures live in conftest.py; these are plain functions and constants.)
"""

from __future__ import annotations

import datetime as dt
import shutil
from pathlib import Path

import numpy as np
import pytest

from rafostrack.config import load_config
from rafostrack.errors import InputError, Warnings
from rafostrack.io.csv_mission import read_arrivals, read_beacons, read_floats
from rafostrack.motion import ClockWalk, IntegratedOU, RandomWalk

try:
    from hypothesis import HealthCheck, settings
    from hypothesis import strategies as st
except ImportError:  # pragma: no cover - hypothesis is a test dependency
    st = None

MODEL = load_config().model
BEACONS = "beacon_id,lat,lon,offset_s,start,end\nA,-58,-100,0,,\nB,-56,-95,600,2009-01-01,\n"
FLOATS = "float_id,launch_time,launch_lat,launch_lon,window_s,max_signals\nf1,2009-01-01T00:00:00Z,-57,-98,4000,3\n"
ARRIVALS = "time,toa_s\n2009-01-02T00:00:00Z,100\n2009-01-02T00:00:00Z,700\n2009-01-03T00:00:00Z,\n"


def write(path: Path, text: str, newline: str = "\n", bom: bool = False) -> Path:
    path.write_bytes((b"\xef\xbb\xbf" if bom else b"") + text.replace("\n", newline).encode())
    return path


def read_small(tmp_path: Path, arrivals: str = ARRIVALS, beacons: str = BEACONS, floats: str = FLOATS):
    """Read a small mission; returns (record, warnings)."""
    table = read_beacons(write(tmp_path / "beacons.csv", beacons))
    info = read_floats(write(tmp_path / "floats.csv", floats), MODEL)["f1"]
    warnings = Warnings()
    record = read_arrivals(write(tmp_path / "f1.csv", arrivals), info, table, warnings)
    return record, warnings


def error_of(func, *args) -> str:
    with pytest.raises(InputError) as err:
        func(*args)
    message = str(err.value)
    assert message and len(message.splitlines()) == 1
    return message


def daily_rows(start: str, days: int, toas: str = "100,700") -> str:
    """Arrival rows: one window a day from `start`, each with the given TOAs."""
    t0 = dt.datetime.fromisoformat(start)
    rows = []
    for d in range(days):
        t = (t0 + dt.timedelta(days=d)).strftime("%Y-%m-%dT%H:%M:%SZ")
        rows += [f"{t},{toa}" for toa in toas.split(",")]
    return "time,toa_s\n" + "\n".join(rows) + "\n"


def simulated_mission_dir(out: Path, seed: int, days: int = 20, particles: int = 200) -> Path:
    """`rafostrack simulate` into `out` (one synthetic float), tracked with `particles`
    particles (written to its rafostrack.toml)."""
    from click.testing import CliRunner

    from rafostrack.cli import main

    result = CliRunner().invoke(main, ["simulate", str(out), "--days", str(days), "--seed", str(seed)])
    assert result.exit_code == 0, result.output
    with open(out / "rafostrack.toml", "a") as fh:
        fh.write(f"\n[filter]\nparticles = {particles}\n")
    return out


def copy_mission(mission: Path, dest: Path) -> Path:
    shutil.copytree(mission, dest)
    return dest


needs_hypothesis = pytest.mark.skipif(st is None, reason="hypothesis is not installed")


def fuzz_settings(n: int = 200):
    return settings(
        max_examples=n,
        deadline=None,
        derandomize=True,
        database=None,
        suppress_health_check=list(HealthCheck),
    )


def only_input_error(func, *args) -> None:
    try:
        func(*args)
    except InputError as exc:
        message = str(exc)
        assert message.strip() and len(message.splitlines()) == 1, repr(message)


def timing_free(run: dict) -> dict:
    """run.json without its wall-clock figures (top-level keys ending in `_s`)."""
    return {k: v for k, v in run.items() if not k.endswith("_s")}


def parquet_bytes(directory: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(directory.glob("*.parquet"))}


def rts_smoother(
    y: np.ndarray, tr, h: np.ndarray, r: float, m0: np.ndarray, p0: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Exact smoothed means and covariances of x_t = A x_{t-1} + b + N(0, Q), y_t = H x_t +
    N(0, r I), x_0 ~ N(m0, p0): the Kalman filter, then the Rauch-Tung-Striebel recursions."""
    a, b, q = tr.A, tr.b, tr.Q
    n, d = len(y), len(m0)
    m_f, p_f, m_p, p_p = np.empty((n, d)), np.empty((n, d, d)), np.empty((n, d)), np.empty((n, d, d))
    m, p = m0, p0
    for t in range(n):
        m_p[t], p_p[t] = a @ m + b, a @ p @ a.T + q
        s = h @ p_p[t] @ h.T + r * np.eye(len(h))
        gain = p_p[t] @ h.T @ np.linalg.inv(s)
        m = m_p[t] + gain @ (y[t] - h @ m_p[t])
        p = (np.eye(d) - gain @ h) @ p_p[t]
        m_f[t], p_f[t] = m, p
    m_s, p_s = m_f.copy(), p_f.copy()
    for t in range(n - 2, -1, -1):
        c = p_f[t] @ a.T @ np.linalg.inv(p_p[t + 1])
        m_s[t] = m_f[t] + c @ (m_s[t + 1] - m_p[t + 1])
        p_s[t] = p_f[t] + c @ (p_s[t + 1] - p_p[t + 1]) @ c.T
    return m_s, p_s


# One model of each kind, at settings where the smoother clearly differs from the filter.
LINEAR_GAUSSIAN_CASES = {
    "random_walk": RandomWalk(5.0),
    "ou": IntegratedOU(velocity_sd_km_per_day=6.0, decorrelation_days=4.0, mean_current_km_per_day=(3.0, -1.0)),
}
# The float clock in the state (the first pass's `ClockWalk`), about a drift model.
CLOCKED_CASES = {"ou+clock": ClockWalk(LINEAR_GAUSSIAN_CASES["ou"], 2.0, 1.0)}
